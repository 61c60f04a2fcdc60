"""Independent reference solutions (exact formulas, ODE and Volterra solves): one home for all of them.

* :mod:`.rod` — the 1D rod of both models: :func:`tp1_exact` (Test Problem 1 in closed form),
  :func:`rod_ode` (any Model A rod scene, the reduced ODE by Radau), :func:`rod_memory` (a Model B
  rod scene, the scalar Volterra inclusion), :func:`rod_reference` (whichever fits the scene).
* :mod:`.volterra` — the Volterra solvers behind :func:`rod_memory` (Prony ODE, product trapezoid rule).
* :mod:`.modal` — :func:`modal_linear`, the exact-in-time solution of K_A u' + K_G u = t F1.
"""
from .modal import modal_linear
from .rod import RodSolution, rod_memory, rod_ode, rod_reference, tp1_exact

__all__ = ["RodSolution", "tp1_exact", "rod_ode", "rod_memory", "rod_reference", "modal_linear"]
