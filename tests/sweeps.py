"""Property sweeps that count: run a hypothesis strategy through a check, tally the cases tried
and the failures (instead of stopping at the first), and report them.

The default run uses few, derandomized examples (CI sees the same cases every time); the
``slow`` sweeps use many. ``COMPANION_SWEEP_REPORT=FILE`` appends one JSON line per family
(``family``, ``tried``, ``failed``, the first failures) to FILE.
"""

from __future__ import annotations

import json
import os

from hypothesis import HealthCheck, given, settings

#: Examples per family in the default run and in the slow sweep (``COMPANION_SWEEP_EXAMPLES``
#: overrides the latter).
QUICK, SLOW = 40, int(os.environ.get("COMPANION_SWEEP_EXAMPLES", "1000"))


def sweep(family: str, strategy, check, examples: int) -> tuple[int, list]:
    """Feed ``examples`` cases of ``strategy`` to ``check`` (which asserts); return the
    number tried and the failures ``(case, message)``. Hypothesis does not shrink here: every
    case is counted once."""
    tried, failed = 0, []

    @settings(max_examples=examples, derandomize=True, database=None, deadline=None,
              suppress_health_check=list(HealthCheck), phases=("generate",))
    @given(strategy)
    def run(case):
        nonlocal tried
        tried += 1
        try:
            check(case)
        except AssertionError as exc:
            failed.append((case, str(exc).splitlines()[0] if str(exc) else "assertion"))

    run()
    report = os.environ.get("COMPANION_SWEEP_REPORT")
    if report:
        with open(report, "a", encoding="utf-8") as fh:
            fh.write(json.dumps({"family": family, "tried": tried, "failed": len(failed),
                                 "first": [f"{c!r}: {m}" for c, m in failed[:5]]},
                                default=repr) + "\n")
    return tried, failed


def assert_none_failed(family: str, tried: int, failed: list) -> None:
    assert tried > 0, f"{family}: no case was tried"
    assert not failed, (f"{family}: {len(failed)} of {tried} cases failed, e.g.\n"
                        + "\n".join(f"  {c!r}: {m}" for c, m in failed[:8]))
