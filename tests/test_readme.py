"""The README's Python quickstart runs as printed and says what it prints."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


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
