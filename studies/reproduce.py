"""Reproduce the paper's Test Problems 1–5 into data/reproduction (Figs. 2–19, archives, key numbers).

Run (from the repository root)::

    python studies/reproduce.py all            # the same as: workbench reproduce all --out data/reproduction
    python studies/reproduce.py tp5 --h 0.05   # reduced size (any option of `workbench reproduce`)

The work is :mod:`workbench.paper.reproduction`; the report is studies/README.md.
"""
import sys
from pathlib import Path

from workbench.cli import main

if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--out" not in argv:
        argv += ["--out", str(Path(__file__).resolve().parent.parent / "data" / "reproduction")]
    sys.exit(main(["reproduce", *argv]))
