"""--help gives the range of every numeric flag, taken from the table the checks use
(companion.apps.flags.FLAGS), and docs/parameters.md gives the range of every parameter."""

import argparse

from companion.apps.cli import parser
from companion.apps.flags import FLAGS

#: Metavars of flags that take numbers.
NUMERIC = {"S", "M", "RAD", "X,Y,THETA", "V1,V2", "MPS", "N", "X", "SEED"}


def subcommands():
    ap = parser()
    action = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices.items()


def test_every_numeric_flag_shows_its_range_in_help():
    seen = set()
    for name, sub in subcommands():
        for action in sub._actions:
            flag = next((o for o in action.option_strings if o.startswith("--")), None)
            numeric = action.type in (int, float) or action.metavar in NUMERIC
            if flag is None or not numeric:
                continue
            assert flag in FLAGS, f"companion {name} {flag}: no range in apps.flags.FLAGS"
            metavar = {"--start": "X", "--speeds": "V"}.get(flag, action.metavar)
            expected = FLAGS[flag].text(metavar)
            assert expected in " ".join(action.help.split()), \
                f"companion {name} {flag}: help {action.help!r} lacks {expected!r}"
            seen.add(flag)
    assert seen == set(FLAGS), f"ranges without a flag: {set(FLAGS) - seen}"


def test_a_value_outside_the_help_range_is_rejected_with_that_range(capsys):
    from companion.apps.cli import main
    for argv, flag, metavar in [(["soak", "--seed", "-1"], "--seed", "N"),
                                (["convergence", "--settle-limit", "-5"], "--settle-limit",
                                 "S"),
                                (["pedestrians", "--min-speed", "9"], "--min-speed", "MPS")]:
        assert main(argv + ["--out", "/nonexistent/never"]) == 2
        err = capsys.readouterr().err
        assert f"{flag}: expected {FLAGS[flag].text(metavar)}" in err, err


def test_every_parameter_row_gives_the_range_its_check_uses():
    import re
    from pathlib import Path

    from companion.config import field_docs
    from companion.params import Params
    text = (Path(__file__).resolve().parents[1] / "docs" / "parameters.md").read_text()
    for key, _, _, _, allowed in field_docs(Params):
        row = next(line for line in text.splitlines() if line.startswith(f"| `{key}` |"))
        cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", row)]
        assert cells[4] == allowed, f"{key}: docs give {cells[4]!r}, the check {allowed!r}"
