"""The README's Python quickstart runs as printed and says what it prints; its architecture map
names every module."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PACKAGE = ROOT / "src" / "companion"


def test_quickstart_runs(capsys):
    text = README.read_text()
    block = re.search(r"## Python quickstart\s+```python\n(.*?)```", text, re.S).group(1)
    scope: dict = {}
    exec(compile(block, "README.md quickstart", "exec"), scope)
    printed = capsys.readouterr().out.split("\n")
    assert float(printed[0]) < 0.02                      # figure-8 RMSE rho, m
    v, omega, status = printed[1].split()
    assert abs(float(v)) <= 1.5 and abs(float(omega)) <= 1.6 and status == "ok"
    assert 0.0 < scope["worst"] < 0.5                    # every start converged


def modules() -> set[str]:
    """Every module of the package by its stem (``front_end`` for ``perception/front_end.py``)
    and every subpackage by its folder name; data and TOML files are not modules."""
    names = {p.stem for p in PACKAGE.rglob("*.py")
             if p.name != "__init__.py" and "__pycache__" not in p.parts}
    names |= {p.parent.name for p in PACKAGE.rglob("__init__.py")
              if p.parent != PACKAGE and "__pycache__" not in p.parts}
    return names


def test_architecture_map_names_every_module():
    text = README.read_text()
    found = re.search(r"^## Architecture\s*\n+```[^\n]*\n(.*?)^```", text, re.S | re.M)
    assert found, "README.md has no code block under '## Architecture'"
    block = found.group(1)
    missing = sorted(name for name in modules()
                     if not re.search(rf"(?<!\w){re.escape(name)}(?!\w)", block))
    assert not missing, ("README.md's architecture map does not name these modules of "
                         f"src/companion: {', '.join(missing)}")


def test_the_measured_table_is_what_companion_run_prints(tmp_path):
    """Every row of the README's table of ``companion run`` results, run again: RMSE rho and
    alpha as printed there (to the digits shown)."""
    import json

    from companion.apps.cli import main

    text = README.read_text()
    table = text.split("Measured with `companion run`")[1].split("\n\n")[1]
    rows = [r.split("|")[1:5] for r in table.splitlines()[2:]]
    assert len(rows) >= 5
    for scenario, controller, rho, alpha in rows:
        name = scenario.split()[0]
        controller = controller.split()[0]
        out = tmp_path / f"{name}-{controller}"
        assert main(["run", name, "--controller", controller, "--out", str(out)]) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        rho_cm, digits = float(rho.split()[0]), rho.split()[0].partition(".")[2]
        assert round(100 * metrics["rmse_rho_m"], len(digits)) == rho_cm, (name, controller)
        shown = alpha.split()[0]
        assert f"{metrics['rmse_alpha_rad']:.{len(shown.partition('.')[2])}f}" == shown, \
            (name, controller)
