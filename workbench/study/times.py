"""When a study's cases are recorded and compared: the times their grids share, and what is done where they share few.

Whole fields are compared at up to ``n_compare`` times spread over the points every case's grid, and the reference
run's, has (:func:`common`). Grids that do not nest share few: memory_rod at k = 0.08, 0.04, 0.02 (13 steps of
0.0769 s beside 25 and 50) shared t = 1 alone, where its error was 2900 times below that of the same k = 0.04 case
compared at ten times, and the order came out 1.75 for a first-order rule (found by an outside pass). Where the
grids share fewer than half of the times asked for (of the coarsest grid's points, where it has fewer),
:func:`check` compares each case at its own grid's points nearest them against a solution, which is known at any
time (:func:`compared`), and refuses the sweep against a run, naming the grids (``n_compare`` given as the number
the grids share accepts it).
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError


def common(study):
    """(record times, comparison times): the coarsest fixed grid's points that every fixed grid has, and up to
    n_compare of them spread over (0, T]. Error-controlled cases have no grid: they are compared (and recorded) at
    the comparison times, which their step controller lands on; with only such cases, or where each case is compared
    at its own points (:func:`check`), these are n_compare equal stretches of [0, T]."""
    from ..schemes.stepping import time_grid

    T = study.scene["T"]
    ks = _fixed_steps(study)
    if not ks or study.own_times:
        every = np.linspace(0.0, T, study.n_compare + 1)
        return every, every[1:]
    grids = [time_grid(T, k) for k in ks]
    coarse = grids[int(np.argmin([len(g) for g in grids]))]
    shared = np.array([t for t in coarse if all(np.min(np.abs(g - t)) <= 1e-9 * T for g in grids)])
    idx = np.unique(np.round(np.linspace(0, len(shared) - 1, study.n_compare + 1)).astype(int))[1:]
    return shared, shared[idx]


def _fixed_steps(study) -> list:
    every = study.cases + (study.reference.cases() if study.reference else [])
    return sorted({c.k for c in every if not study._adaptive(c)}, reverse=True)


def check(study) -> bool:
    """Whether each case is compared at its own grid's points (True: grids that share too few times, against a
    solution); a ParameterError, before any work, where they share too few against a run (module docs)."""
    from ..schemes.stepping import time_grid

    T, fixed = study.scene["T"], _fixed_steps(study)
    if study.n_compare == 1 or not fixed:
        return False
    compare = common(study)[1]
    coarse = min(len(time_grid(T, k)) - 1 for k in fixed)
    if 2 * len(compare) >= min(study.n_compare, coarse):
        return False
    if study.reference.kind == "solution":
        return True
    grids = ", ".join(f"k = {k:g}: {len(time_grid(T, k)) - 1} steps of {T / (len(time_grid(T, k)) - 1):.4g} s"
                      for k in fixed[:4]) + (", ..." if len(fixed) > 4 else "")
    raise ParameterError(f"the cases' step grids (and the reference's) share {len(compare)} time"
                         f"{'s' if len(compare) > 1 else ''} to compare fields at (t = "
                         f"{', '.join(f'{t:.4g}' for t in compare[:5])}{', ...' if len(compare) > 5 else ''}), of "
                         f"n_compare = {study.n_compare} asked for ({grids}): errors seen that rarely can miss the "
                         "error entirely. Give steps whose grids nest (T / k whole numbers, each grid a part of "
                         f"the finer ones), or n_compare = {len(compare)} to compare there")


def compared(study, case, compare) -> list:
    """The times ``case`` is compared at: the study's comparison times ``compare``, or, where each case is compared
    at its own points (:func:`check`), its grid's points nearest them (memory_rod at k = 0.08 against its Volterra
    solution: 0.0769, 0.231, ...)."""
    if not study.own_times or study._adaptive(case):
        return [float(t) for t in compare]
    from ..schemes.stepping import time_grid

    grid = time_grid(study.scene["T"], case.k)
    return sorted({float(grid[np.argmin(np.abs(grid - t))]) for t in compare} - {0.0})


def record_times(study, case, record, compare) -> list:
    """The times ``case`` records at: the shared ones, or (error-controlled, or compared at its own points) t = 0
    and its comparison times."""
    if study._adaptive(case) or study.own_times:
        return [0.0] + compared(study, case, compare)
    return list(record)
