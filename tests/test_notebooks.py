"""The exploration notebooks (jupytext percent-format .py files in studies/notebooks), executed in a real kernel.

Each notebook is converted with jupytext and run by nbclient in an IPython kernel, as Jupyter would run it
(inline matplotlib, no backend forced), at small size (WORKBENCH_NOTEBOOK_SMALL=1). The test asserts what
the reader sees: no error output, and an inline PNG for every cell that draws a figure (a library module
that picked the Agg backend at import made every figure vanish, while a script run of the same file passed).
"""
import os
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "studies" / "notebooks").glob("*.py"))
#: Source fragments of the cells that must show a figure inline.
DRAWS = ("plotting.", "plt.subplots", "fig, ax")


def execute(path, tmp_path, monkeypatch):
    monkeypatch.setenv("WORKBENCH_NOTEBOOK_SMALL", "1")
    monkeypatch.delenv("MPLBACKEND", raising=False)  # as in Jupyter: the kernel chooses the inline backend
    nb = jupytext.read(path)
    client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    client.execute()
    return [c for c in nb.cells if c.cell_type == "code"]


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_shows_its_figures(path, tmp_path, monkeypatch):
    cells = execute(path, tmp_path, monkeypatch)
    drawing = [c for c in cells if any(f in c.source for f in DRAWS)]
    assert drawing, "the notebook draws nothing?"
    for cell in cells:
        kinds = {o["output_type"] for o in cell.get("outputs", [])}
        assert "error" not in kinds, cell.source
    for cell in drawing:
        images = [o for o in cell.get("outputs", []) if "image/png" in o.get("data", {})]
        assert len(images) == 1, f"expected one inline figure from:\n{cell.source}\ngot {len(images)}"


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 2


def test_library_modules_pick_no_backend():
    """Only command-line entry points may choose a matplotlib backend."""
    root = Path(__file__).resolve().parents[1] / "workbench"
    offenders = [p.name for p in root.rglob("*.py") if "matplotlib.use(" in p.read_text() and p.name != "cli.py"]
    assert not offenders
