"""Reproduce the paper's Test Problems 1–5 into data/reproduction (Figs. 2–19, archives, key numbers).

Run (from the repository root)::

    python studies/reproduce.py all            # the same as: workbench reproduce all --out data/reproduction
    python studies/reproduce.py tp5 --h 0.05   # reduced size (any option of `workbench reproduce`)
    python studies/reproduce.py tp1 --out=/tmp/repro   # elsewhere (--out DIR or --out=DIR)

The work is :mod:`workbench.paper.reproduction`; the report is studies/README.md.
"""
import argparse
import sys
from pathlib import Path

from workbench.cli import main

DATA = Path(__file__).resolve().parent.parent / "data" / "reproduction"

if __name__ == "__main__":
    # --out as argparse reads it (--out DIR, --out=DIR): only its default differs from `workbench reproduce`
    out = argparse.ArgumentParser(add_help=False)
    out.add_argument("--out", default=str(DATA))
    known, rest = out.parse_known_args(sys.argv[1:])
    sys.exit(main(["reproduce", *rest, "--out", known.out]))
