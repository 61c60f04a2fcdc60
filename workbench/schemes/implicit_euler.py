"""Backward Euler with implicit contact: the stable scheme (``scheme = "implicit"``).

Per step n (k = t_n - t_{n-1}), with M = K_A / k + K_G:

    M u_n + j(beta_n, u_n, .) = F_n + K_A u_{n-1} / k              (u_n implicit)
    beta_n = exact solution at t_n of beta' = -(gamma beta r2 - eps_a)_+ from beta_{n-1},
             with r2 = P_B[R(u_n,nu)^2] frozen over the step            (exponential Euler)
    sigma_n = P_Q [A eps(v_n) + G eps(u_n)],  v_n = (u_n - u_{n-1}) / k

How beta_n enters the traction depends on whether the step resolves debonding
(k gamma_nu L^2 beta0 <= 0.1, see ``bonding_resolved`` in the results):

* resolved: a predictor, the same exponential update evaluated with u_{n-1}
  (it lowers beta by at most e^-0.1), one Newton solve for u_n, then beta_n
  from u_n;
* not resolved: u_n is solved with beta_{n-1}, beta_n computed from it, u_n
  solved again with that beta_n, and beta_n recomputed. A predictor would pick
  the wrong, fully debonded branch there: the glue must act at full strength
  first (found by the extremes suite: beta = 0 instead of 0.854 on tp1 with
  gamma_nu = 1e4, k = 0.01).

Measured on the slab of the stability issue (gamma_nu = 20, k = 0.01,
resolved): tip error 2.6% with beta_{n-1} alone, 1.2% with the predictor and
with the corrector; iterating the coupling to a fixed point (30 passes)
changes the result by < 0.05%. Newton starts from the linearly extrapolated
contact displacement, which usually has the right active set.
The bonding update (:meth:`workbench.physics.bonding.BondingLaw.exponential_step`)
never leaves [0, beta_{n-1}], however stiff gamma is; it is exact while |u_nu| >= L
(the saturated regime that dominates debonding) and first order otherwise.
The displacement system is solved by semismooth Newton condensed onto the contact
dofs (:mod:`workbench.discrete.condensation`): M is assembled from K_A and K_G and factored
once per step size, each Newton iteration costs one small dense SPD solve, each step
two back-substitutions. Newton iterations are recorded per step
(``newton_iterations``); failure to converge stops the run with the step and time.
"""
from __future__ import annotations

import numpy as np

from ..discrete import solvers
from ..discrete.condensation import CondensedNewton, CondensedSystem, ContactOperator, CoupledNewton, SchurOperator
from ..physics.ops import NP
from .base import ErrorControlled
from .candidates import Candidates
from .facet_candidates import FacetCandidates
from .halfspace import HalfSpace
from .model_a import KelvinVoigtScheme, kink_event
from .step_operators import SharedFactor, StepOperator, StepOperators


class ImplicitEuler(ErrorControlled, KelvinVoigtScheme):
    """Backward Euler, contact and adhesion implicit (module docs).

    The step solves a0 K_A u_n + K_G u_n + j(beta_n, u_n, .) = F_n - K_A h_n, with
    (a0, h_n) from :meth:`coefficients` (backward Euler: a0 = 1/k, h_n = -u_{n-1}/k;
    :class:`~workbench.schemes.bdf2.BDF2` overrides them), so that v_n = a0 u_n + h_n.
    The matrix a0 K_A + K_G is factored and condensed once per distinct a0 (a small cache,
    so that an adaptive run that returns to a step size reuses it); where A = tau G, K_G's one
    factor, with its condensed stiffness and the candidates it keeps, serves every a0
    (:class:`~workbench.schemes.step_operators.SharedFactor`).
    """

    name = "implicit"
    order = 1
    max_passes = 2  # pass 1 with beta_{n-1}, pass 2 with the beta_n it gives (see the module docs)
    beta_tol = 1e-9  # coupling tolerance on beta (far below the O(k) error)
    #: factored operators kept (per a0): 16 on small meshes (measured on the slab of issue 11, adaptive BDF2 at
    #: rtol 1e-3: 173 factorisations in 314 solves with 4, 89 with 16), 4 from 20000 dofs on (memory: each holds a
    #: sparse factor and the dense condensed matrix), and never more than fit FACTOR_BYTES together
    #: (:func:`~workbench.discrete.solvers.factors_kept`: one where each is large)
    cache_size = 16
    cache_size_large = 4

    def __init__(self, d):
        super().__init__(d)
        if d.ndof > 20000:
            self.cache_size = self.cache_size_large
        self.rhs = d.u.vec.CreateVector()
        self.rhs_np = self.rhs.FV().NumPy()
        self.work = d.u.vec.CreateVector()
        self.z = np.zeros(d.ndof)
        self.u_prev = np.zeros(d.ndof)
        self.lift = d.u.vec.CreateVector()
        # the contact problem is solved on the view of the body that holds its side (module docs; on several
        # processes rank 0's, while the other ranks serve its back-substitutions: self.exchange)
        self.exchange = d.exchange()
        view = self.exchange.view
        self.op = ContactOperator(view) if self.exchange.solves and view.side is not None else None
        size = self.exchange.share(self.op.size if self.op is not None else 0)
        self.contact = size > 0
        self.exchange.bind(self.op.C if self.op is not None else ())
        self.method = d.step_solver()
        self.cache_size = solvers.factors_kept(d.dim, d.ndof_global, self.method, self.cache_size)
        self.coupled = self.contact and d.numerics.coupled_contact(size, self.method, solvers.forms_schur(self.method))
        self.bonding = d.model.bonding
        self.shared = SharedFactor.of(d, self.method)  # (A = tau G: one factor for every a0)
        self.candidates = FacetCandidates.of(d, self.op, self.method, self.coupled, self.shared is not None)
        n = d.numerics
        own = None if n.adaptive else StepOperators.key(self._constant_a0(n.k))
        self.operators = StepOperators(self.cache_size, own, self.candidates, self.shared is not None)
        self.M = self.newton = self.solver = self.split = self.kept = None  # (the step's, from _prepare)
        self.iterations = self.passes = self.inner = 0
        self.resolved = True

    def preflight(self, k_max: float) -> dict:
        used = {"contact_solver_used": "coupled" if self.coupled else "condensed"} if self.d.side is not None else {}
        used |= Candidates.planned(len(self.candidates.C) if self.candidates else 0)
        return self.bonding_check(k_max) | used

    def used(self) -> dict:
        """The step operators' linear solver (the same for every a0), and the contact candidates (.facet_candidates)."""
        used = Candidates.attrs(self.candidates) if self.contact else {}
        return used | ({"linear_solver": self.solver.name} if self.solver is not None else {})

    # -- the multistep formula -------------------------------------------------------------------------------
    def coefficients(self, k: float):
        """(a0, history) with v_n = a0 u_n + h_n; backward Euler: a0 = 1/k, h_n = -u_{n-1}/k (no history term)."""
        return 1.0 / k, None

    def _rate_offset(self, history):
        """w_n = a0 u_{n-1} + h_n, the rate the formula gives for u_n = u_{n-1}: zero for backward Euler."""
        return None

    def _velocity(self, du, a0, w):
        """v_n = a0 (u_n - u_{n-1}) + w_n."""
        return a0 * du if w is None else a0 * du + w

    def _prepare(self, a0: float, k: float) -> None:
        """The operator a0 K_A + K_G of the step (:class:`~workbench.schemes.step_operators.StepOperators`)."""
        if not self.operators.holds(a0):
            self.M = self.solver = self.newton = self.split = self.kept = None  # (freed with theirs, if dropped)
        op = self.operators.get(a0, self._build)
        self.M, self.solver, self.newton, self.split, self.kept = op.M, op.solver, op.newton, op.split, op.kept
        self.resolved = self.bonding is None or self.bonding.resolved(k, self.d.model.beta0)

    def _build(self, a0: float, keep: bool) -> StepOperator:
        """a0 K_A + K_G from the assembled matrices (same sparsity), factored, with its contact solver; the
        factorization keeps the contact candidates where ``keep``."""
        d, M = self.d, None
        if self.shared is None or d.moves_clamp:  # (a shared factor needs the matrix for no factor, only for a lift)
            M = d.viscous.mat.CreateMatrix()
            M.AsVector().data = a0 * d.viscous.mat.AsVector() + d.elastic.mat.AsVector()
        solver = d.step_factor(M) if self.shared is None else self.shared.solver(a0)
        diagonal = self.exchange.operator_diagonal(a0) if self.coupled else None  # (on every process: it gathers)
        newton = self.exchange.run(lambda: self._newton(solver, diagonal), solver) if self.contact else None
        split = solver.split(self.op.C) if self.op is not None and not self.coupled else None
        kept = self.candidates.operator(solver) if keep else None
        return StepOperator(M, solver, newton, split, kept)

    def _newton(self, solver, diagonal=None):
        """The contact solver of the operator ``solver`` solves (where the contact problem is solved); ``diagonal``:
        the operator's (the coupled solver's preconditioner)."""
        view, proxy = self.exchange.view, self.exchange.proxy(solver)
        if self.coupled:
            halfspace = None
            if view.dim == 3 and not self.op.tangential:
                halfspace = HalfSpace.of_body(*self.op.dof_points(), self.op.d.geometry,
                                              HalfSpace.largest_for(view.ndof, self.method))
            return CoupledNewton(SchurOperator(proxy, view.ndof, self.op.C, diagonal=diagonal), self.op,
                                 halfspace=halfspace)
        return CondensedNewton(CondensedSystem(proxy, view.ndof, self.op.C), self.op)

    def _cache_state(self) -> list:
        return self.operators.state()

    def _restore_cache(self, cache: list) -> None:
        self.operators.restore(cache)

    def _constant_a0(self, k: float) -> float:
        """a0 of a step of size k after steps of the same size: 1/k."""
        return 1.0 / k

    # -- one step ---------------------------------------------------------------------------------------------
    def step(self, t_prev: float, t_next: float) -> None:
        """One step, solved for the increment du = u_n - u_{n-1}:

            M du + j(beta_n, u_{n-1} + du, .) = F_n - K_G u_{n-1} - K_A w_n,   M = a0 K_A + K_G,

        which is the formula of :meth:`coefficients` rewritten: du carries its own relative
        precision, where u_n solved whole carries that of u (measured on the slab of issue 11:
        the increments of steps of 1e-7 s were noise at 5e-9 |u|, which error control read as
        a local error).
        """
        d = self.d
        k = t_next - t_prev
        a0, history = self.coefficients(k)
        self._prepare(a0, k)
        u = d.u.vec.FV().NumPy()
        self.u_prev[:] = u
        w = self._rate_offset(history)
        d.load_vector(t_next, self.rhs)  # rhs = F_n - K_G u_{n-1} - K_A w_n
        self.work.data = d.elastic.mat * d.u.vec
        self.rhs_np -= self.work.FV().NumPy()
        if w is not None:
            self.lift.FV().NumPy()[:] = w
            self.work.data = d.viscous.mat * self.lift
            self.rhs_np -= self.work.FV().NumPy()
        if d.moves_clamp:  # du = delta(t_n) - delta(t_{n-1}) at the rod end x = 0
            lift = d.lift(t_next, self.lift.FV().NumPy())
            lift[d.dirichlet_dofs] -= u[d.dirichlet_dofs]
            self.work.data = self.M * self.lift
            self.rhs_np -= self.work.FV().NumPy()
        self.iterations = self.passes = self.inner = 0
        if not self._on_candidates(u, k, t_next):
            if self.split is not None:  # (one solve in two parts: z at the contact dofs now, the rest from du there)
                self.z[self.op.C] = self.split.free_displacement(self.rhs_np)
            else:
                self.solver.solve(self.rhs_np, self.z)  # z = du without the contact forces
            if d.moves_clamp:
                self.z[d.dirichlet_dofs] = d.dirichlet_value(t_next) - u[d.dirichlet_dofs]
            if self.contact:
                self._contact(u, k, t_next)
        u[:] = self.u_prev + self.z
        if not self.contact and self.bonding is not None:
            self._update_beta(k, d.beta.vec.FV().NumPy()[d.beta_dofs].copy())
        d.v.vec.FV().NumPy()[:] = self._velocity(self.z, a0, w)
        self.k_last = k

    def _contact(self, u: np.ndarray, k: float, t_next: float) -> None:
        """The contact forces of the step by the condensed semismooth Newton, coupled with beta_n (the passes of the
        module docs), taken off the contact-free increment ``self.z``; ``u`` holds u_{n-1} (its contact dofs the
        solution, for the bonding update). The Newton iteration runs where the contact problem is solved, on the
        contact dofs of the view (:attr:`exchange`); beta is updated where its facets are."""
        d, x = self.d, self.exchange
        C = self.op.C if self.op is not None else None
        z_C = x.gather(u + self.z)
        z_C = z_C[C].copy() if x.solves else None
        u_C = extrapolated(self.exchange, u, self.history, C, k)
        beta = d.beta.vec.FV().NumPy() if d.beta is not None else None
        beta_old = beta[d.beta_dofs].copy() if beta is not None else None
        passes = self.max_passes
        if beta is not None and self.resolved:
            self._predict_beta(k, beta_old)  # drops beta by at most e^-0.1 here
            passes = 1
        if self.newton is not None:
            self.newton.iterations = self.newton.linear_iterations = 0
        for self.passes in range(1, passes + 1):
            x.sync_beta()
            f_C = x.run(lambda: self.newton.solve(u_C, z_C, t_next, d.scene.name), self.solver)
            if beta is None:
                break
            x.put(u, on_view(self.exchange, C, u_C))  # the bonding update reads u on the contact side only
            previous = beta[d.beta_dofs].copy()
            self._update_beta(k, beta_old)
            if d.world.max(np.abs(beta[d.beta_dofs] - previous).max(initial=0.0)) <= self.beta_tol:
                break
        n = self.newton
        self.iterations, self.inner = x.share(n.iterations if n is not None else 0), n.linear_iterations if n else 0
        if self.split is not None:
            return self.split.expand(u_C - self.u_prev[C], self.z)  # du from its values at the contact dofs
        out = np.zeros(d.ndof)
        self.solver.solve(x.spread(on_view(self.exchange, C, f_C)), out)
        self.z -= out

    def prescribed_response(self, u_pred: np.ndarray):
        return end_response(self.d, self.M, self.solver, u_pred) if self.d.moves_clamp and self.M is not None else None

    def _on_candidates(self, u: np.ndarray, k: float, t_next: float) -> bool:
        """``self.z`` solved on the contact candidates (.facet_candidates); False where none, or they missed."""
        if self.kept is None or self.candidates.missed:
            return False
        guess = lambda C: extrapolated(self.exchange, u, self.history, C, k)  # noqa: E731
        du = self.candidates.step(self.kept, self.rhs_np, u, guess, t_next, self.d.scene.name)
        if du is not None:
            self.z[:] = du
            self.iterations, self.inner, self.passes = self.kept[1].iterations, self.kept[1].linear_iterations, 1
        return du is not None

    # -- the bonding field --------------------------------------------------------------------------------------
    def _r2(self, u):
        """P_B[R_b(u_nu)^2] at the facets (midpoint rule), in facet order."""
        rs = self.d.rate_side
        r = self.bonding.r(NP, rs.u_nu(u))
        out = np.empty(len(self.d.beta_dofs))
        out[rs.element] = r * r
        return out

    def _predict_beta(self, k: float, beta_old) -> None:
        """The predictor: the bonding update with u_{n-1} (the state the step starts from)."""
        self._update_beta(k, beta_old)

    def _update_beta(self, k: float, beta_old) -> None:
        """beta_n from beta_{n-1} = ``beta_old`` and the current u on the contact side (r2 at the facet midpoints)."""
        d = self.d
        d.beta.vec.FV().NumPy()[d.beta_dofs] = self.bonding.exponential_step(beta_old, self._r2(d.u.vec.FV().NumPy()),
                                                                             k)

    def diagnostics(self) -> dict:
        out = {"newton_iterations": self.iterations, "coupling_passes": self.passes}
        if self.coupled:
            out["linear_iterations"] = self.inner
        return out

    def event(self, start: dict):
        """Where in the last step the contact and bonding laws' kinks were crossed (:func:`.model_a.kink_event`)."""
        return kink_event(self.d, start, self._beta())


def extrapolated(x, u: np.ndarray, history, C, k: float):
    """u at the contact dofs ``C`` of the view of the exchange ``x``, extrapolated linearly from the last two states
    of ``history`` to a step ``k`` (Newton's start: often the right active set); None where the contact problem is
    not solved."""
    u_C, before = x.gather(u), x.gather(history[-2][1]) if len(history) >= 2 else None
    if not x.solves:
        return None
    u_C = u_C[C].copy()
    if before is not None:
        u_C += (k / (history[-1][0] - history[-2][0])) * (u_C - before[C])
    return u_C


def on_view(x, C, values):
    """A dof vector of the view of the exchange ``x`` with ``values`` on the contact dofs ``C`` (None where the solver
    does not run)."""
    if values is None:
        return None
    out = np.zeros(x.view.ndof)
    out[C] = values
    return out


def end_response(d, M, solver, u_pred: np.ndarray) -> np.ndarray:
    """The rod end's predictor miss m = u - ``u_pred`` there, spread by the step's operator ``M`` (factored by
    ``solver``): m at the end, -M_II^-1 M_ID m inside (one back-substitution, :meth:`ImplicitEuler.prescribed_response`).
    A free rod moved by delta(t) moves rigidly, u = delta, which every step meets exactly; its predictor misses by
    delta's curvature, which read as error took backward Euler 149135 steps at rtol 1e-3 for
    delta = -0.1 + 0.03 sin(20 pi t)."""
    D, lift, work = d.dirichlet_dofs, d.u.vec.CreateVector(), d.u.vec.CreateVector()
    miss = lift.FV().NumPy()
    miss[:] = 0.0
    miss[D] = d.u.vec.FV().NumPy()[D] - u_pred[D]
    work.data = M * lift
    out = np.zeros(d.ndof)
    solver.solve(-work.FV().NumPy(), out)
    out[D] = miss[D]
    return out
