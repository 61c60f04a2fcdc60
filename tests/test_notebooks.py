"""The exploration notebooks (jupytext percent-format .py files in studies/notebooks) run at small size."""
import runpy
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")
NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "studies" / "notebooks").glob("*.py"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(path, monkeypatch):
    monkeypatch.setenv("WORKBENCH_NOTEBOOK_SMALL", "1")
    runpy.run_path(str(path), run_name="__main__")
    import matplotlib.pyplot as plt

    plt.close("all")


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 2
