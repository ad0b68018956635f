"""The shape of the source tree: layers that point one way, no import cycles, no god files."""

from pathlib import Path

from importlinter.cli import lint_imports

ROOT = Path(__file__).resolve().parents[1]
#: A source file longer than this holds more than one duty (README, "Architecture").
MAX_LINES = 420


def test_import_contracts_of_pyproject_hold():
    """types <- basics <- model, riccati, perception <- control <- sim <- apps, and no cycles
    between sibling modules at any depth (the contracts in pyproject.toml)."""
    assert lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True) == 0


def test_no_source_file_is_a_god_file():
    sizes = {p.relative_to(ROOT): len(p.read_text().splitlines())
             for p in (ROOT / "src" / "companion").rglob("*.py")}
    assert {p: n for p, n in sizes.items() if n > MAX_LINES} == {}
