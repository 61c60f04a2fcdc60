"""The README's commands are the ones CI runs, and its documented CLI lines work."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    line = next(li.strip() for li in readme.splitlines() if "pytest" in li and "pip install" in li)
    assert line in ci
