"""Checks of a run before any mesh is built: will it fit in memory, and what should the user be warned about.

:func:`resources` estimates the number of displacement dofs from the cell counts and
the element order, and the memory of the factorisation of the constant matrix
(banded Cholesky after RCM on thin structured meshes, nested-dissection-like fill
otherwise, calibrated on measured runs), and refuses a run that cannot fit in the
memory free to the process (the machine's, its job's, ulimit -v's), naming h and the
numbers. :func:`warnings_for` gives the warnings that belong to the scene itself (P1
simplices on a thin body lock).

Examples
--------
>>> import workbench
>>> est = estimate(workbench.scene("slab", h=2e-4).body, order=1)
>>> est.ndof > 4e6 and est.bytes > 1e10
True
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..discrete import pardiso
from ..errors import ParameterError
from ..input.numerics import ADAPT, CONTROL, is_adaptive, may_iterate


@dataclass(frozen=True)
class Estimate:
    ndof: int
    bytes: float


def available_memory(cgroups: str = "/proc/self/cgroup", cgroup_root: str = "/sys/fs/cgroup") -> float:
    """Bytes of memory available to a new allocation, or infinity when unknown (Linux): the least of the machine's
    MemAvailable, what the process's control group (a Slurm job, a container: cgroup v2 memory.max) has left, and
    what its address-space limit (``ulimit -v``) leaves beyond the process's size. MemAvailable alone let a run under
    such a limit be planned as if it had the whole machine (found by an outside pass). ``cgroups`` and
    ``cgroup_root``: where the process's groups and their files are read (the system's)."""
    out = [_meminfo("/proc/meminfo", "MemAvailable:")]
    try:
        with open(cgroups) as f:
            groups = dict(line.strip().split(":", 2)[1:] for line in f if line.count(":") >= 2)
    except OSError:
        groups = {}
    for key, folder, limit, used in (("", "", "memory.max", "memory.current"),  # (cgroup v2, then v1)
                                     ("memory", "memory", "memory.limit_in_bytes", "memory.usage_in_bytes")):
        if key not in groups:
            continue
        root = Path(cgroup_root) / folder / groups[key].lstrip("/")
        try:
            most = (root / limit).read_text().strip()
            if most != "max" and float(most) < 2.0 ** 60:  # (v1 says "no limit" with a number near 2^63)
                # the usage less the file cache the kernel gives back on demand (counted, a job whose files were
                # read looked full: found by an outside pass), as `docker stats` counts it
                stat = dict(line.split() for line in (root / "memory.stat").read_text().splitlines()
                            if len(line.split()) == 2)
                cache = float(stat.get("inactive_file", stat.get("total_inactive_file", 0.0)))
                out.append(float(most) - (float((root / used).read_text()) - cache))
        except (OSError, ValueError):
            pass
    try:
        import resource

        soft, size = resource.getrlimit(resource.RLIMIT_AS)[0], _meminfo("/proc/self/status", "VmSize:")
        if soft != resource.RLIM_INFINITY and math.isfinite(size):  # (no /proc: the limit alone tells nothing)
            out.append(soft - size)
    except (ImportError, OSError, ValueError):
        pass
    return max(0.0, min(out))


def _meminfo(path: str, key: str) -> float:
    """A ``key: N kB`` line of a /proc file, in bytes (infinity where absent)."""
    try:
        with open(path) as f:
            for line in f:
                if line.startswith(key):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return math.inf


def estimate(geometry, order: int, solver: str = "auto", iterative: bool = False) -> Estimate:
    """Displacement dofs and bytes to assemble and factor the constant matrix (order of magnitude; ``mixed``'s factor in
    single precision, half the double one); with ``solver = "cg"``, or ``"auto"`` where it resolves to cg
    (``iterative``: the explicit scheme, :func:`workbench.discrete.solvers.choose`), the matrix copy and the AMG
    hierarchy of the iterative solver instead of a factor."""
    from ..discrete.solvers import PARDISO_WORK, choose, factor_kind, sparse_factor_bytes

    dim = geometry.dim
    vertices = geometry.vertex_count()
    ndof = dim * vertices * order ** dim  # P_p: about p^d scalar dofs per vertex on simplices
    if dim == 1:
        return Estimate(int(ndof), 200.0 * ndof)
    if dim == 2:
        width = 2 * order * (geometry.band_cells() + 1)  # RCM bandwidth across the shorter side (dofs x components)
        banded = 8.0 * ndof * width
        dissection = 8.0 * 30.0 * ndof * max(1.0, math.log2(ndof))
        factor = min(banded, dissection)
    taken = choose(solver, dim, ndof, iterative)  # (the solver auto or the given one takes)
    if dim == 3:  # (its factor, with its work)
        factor = sparse_factor_bytes(dim, ndof, taken) * (PARDISO_WORK if factor_kind(taken) == "pardiso" else 1.0)
    matrices = 8.0 * 3 * ndof * (9 * order ** dim) * dim  # K_A, K_G (and M): about 9 p^d dim entries per row
    if taken == "cg":
        factor = 1.5 * matrices  # SciPy's copy of K_A, the AMG levels, CG's vectors (a run at 271k dofs: 2.1 GB peak)
    return Estimate(int(ndof), factor + matrices)


def resources(scene, model, n_steps: int, processes: int = 1) -> None:
    """Refuse, before any work, a run whose factorisation cannot fit in the free memory (on several MPI
    ``processes`` each holds its part: the estimate of the whole does not apply); and ``solver = 'pardiso'`` or
    ``'mixed'`` where MKL cannot be loaded."""
    if scene["solver"] in ("pardiso", "mixed") and not pardiso.available():
        raise ParameterError(f"solver = {scene['solver']!r} needs Intel MKL, which could not be loaded here (pip "
                             "install mkl, x86-64 only); solver = 'sparsecholesky' is NGSolve's own sparse factor, "
                             "'cg' needs none")
    if processes > 1:
        return
    iterative = may_iterate(scene["scheme"], scene["contact_solver"])
    est = estimate(model.geometry, scene["order"], scene["solver"], iterative)
    free = available_memory()
    _snapshot_memory(scene, model.geometry, est.ndof, free)
    if est.bytes > 0.9 * free:
        which = "h" if not any(scene.values.get(n, 0) for n in model.geometry.cell_names) else "nx/ny/nz"
        raise ParameterError(f"{which} = {scene['h']:g} (order {scene['order']}) gives about {est.ndof:.2g} "
                             f"displacement dofs; assembling and factoring them needs about {est.bytes / 2**30:.3g} GB, "
                             f"more than the {free / 2**30:.3g} GB free to this process: use a larger h or a lower "
                             "order" + ("" if not iterative or scene["solver"] == "cg" else
                                        ", or solver = 'cg' (no factor)"))


def _snapshot_memory(scene, geometry, ndof: int, free: float) -> None:
    """Warn where the field snapshots asked for will not fit in the free memory: they are held until the archive is
    made, and twice while it is (20,000 snapshots of a 3D block, about 64 GB, were taken without a word, and a run
    of 200 under a memory limit did every step and then lost them all, found by an outside pass; what does not fit
    now is dropped at the end, the records kept, :func:`workbench.running.runner._drop_snapshots`)."""
    count = len([t for t in scene["snapshots"] if t < scene["T"]]) + 1  # (and the field at T)
    cells = {1: 1, 2: 2, 3: 6}[geometry.dim] * geometry.vertex_count()  # (simplices per vertex, about)
    each = 8.0 * (ndof + cells * (3 * geometry.dim - 1) + geometry.vertex_count() * geometry.dim)
    if count > 1 and 2.0 * count * each > 0.9 * free:
        import warnings

        warnings.warn(f"snapshots: the {count} field snapshots hold about {count * each / 2**30:.3g} GB until the "
                      f"archive is made, and twice that while it is, more than the {free / 2**30:.3g} GB free to this "
                      "process: ask for fewer (what does not fit is dropped at the end, the records kept)",
                      RuntimeWarning, stacklevel=5)


def refusals(scene, model, numerics, grid, times, processes: int = 1) -> None:
    """Every refusal of a run's inputs that needs its model and its grid, before any work: :func:`resources` and
    :func:`trapezoid_steps` (the longest step: the grid's, set by k or by ``times`` where given; k_max under error
    control). ``times`` with error control is refused: the controller chooses the steps, and the grid was ignored
    without a word (an outside pass)."""
    if times is not None and numerics.adaptive:
        raise ParameterError(f"times = a grid of {len(times)} times with rtol = {numerics.rtol:g}: a grid fixes the "
                             "steps, error control chooses them; give one or the other (record_times= takes the "
                             "times to record at)")
    resources(scene, model, len(grid) - 1, processes=processes)
    longest = (numerics.largest_step, "k_max") if numerics.adaptive else \
        (float(np.max(np.diff(grid))), "k" if times is None else "times")
    trapezoid_steps(scene, model, *longest)


def trapezoid_steps(scene, model, k_max: float, name: str) -> None:
    """Refuse, before any work, steps up to ``k_max`` (the parameter ``name`` sets them) that Model B's trapezoid
    rule cannot take. Its step operator is K_A + sum_i w_i(k) K_Ci, w_i(k) the weight of u_n in term i's memory
    (growing with k: k/2 for a short step, tau_i for a long one). Where the relaxation tensors C_i take stiffness away
    (a negative Prony modulus), a long step leaves the tensor A + sum_i w_i C_i, and the operator, indefinite: the
    step's inequality then has no unique solution, and its factorization fails. The rectangle rule's operator is
    K_A alone.

    >>> import workbench
    >>> sc = workbench.scene("memory_rod", memory_rule="trapezoid", prony=[[-3.0, 0.5]])  # (a = 1: 1 - 3 w(k))
    >>> trapezoid_steps(sc, sc.model_of(), 0.1, "k")  # (w = 0.047: 1 - 3 w > 0; it is 0 at k = 1.41)
    >>> try:
    ...     trapezoid_steps(sc, sc.model_of(), 5.0, "k")
    ... except workbench.ParameterError as err:
    ...     print(str(err).split("; ")[-1])
    allowed: steps below 1.4 s, or memory_rule = 'rectangle'
    """
    memory = model.memory if scene.values.get("memory_rule") == "trapezoid" else None
    if memory is None:
        return
    dim = model.geometry.dim
    A, tensors = model.elastic.voigt(dim), [C.voigt(dim) for C in memory.tensors]
    scale = float(np.abs(A).max())

    def least(k: float) -> float:
        T = A + sum(w * C for w, C in zip(memory.trapezoid_weights(k), tensors))
        return float(np.linalg.eigvalsh(T).min())

    if least(k_max) > 1e-9 * scale:
        return
    low, high = 0.0, k_max  # (the longest step that keeps it definite: A alone is, at k = 0)
    for _ in range(60):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if least(mid) > 1e-9 * scale else (low, mid)
    raise ParameterError(f"{name} = {k_max:g}: with memory_rule = 'trapezoid' a step this long makes the step's "
                         f"operator indefinite (A + sum_i w_i(k) C_i, the memory's share of u_n in it, has the "
                         f"eigenvalue {least(k_max):.3g}); allowed: steps below {low:.2g} s, or "
                         "memory_rule = 'rectangle'")


#: Presets that keep the paper's P1 elements on purpose (documented in docs/choices.md).
PAPER_P1 = ("tp4", "tp5")


def warnings_for(scene, model, used: dict | None = None) -> list:
    """Warnings that belong to the scene: P1 simplices lock in bending on a thin body (the block preset's P1 tip
    was 50 % low at h = 0.05); and values given that have no effect (``used``: the scheme's :meth:`preflight` record,
    what it took, where it is built)."""
    out = []
    g = model.geometry
    # (the paper's own P1 on its presets, however it was given: by default, explicitly, or from a restarted archive)
    paper = scene.base in PAPER_P1 and scene["order"] == 1
    if g.dim >= 2 and scene["order"] == 1 and model.max_order(g.dim) >= 2 and not paper and g.aspect() <= 0.25:
        out.append(f"{scene.name}: P1 elements on a thin body (thickness / length = {g.aspect():.2g}) lock in bending, "
                   "so displacements come out too small (the block at h = 0.05: 50 %; the slab at h = 0.0125: 5 %); "
                   "order = 2 converges at the same cost")
    if scene.values.get("h_contact") and scene["h_contact"] > scene["h"]:
        out.append(f"{scene.name}: h_contact = {scene['h_contact']:g} is coarser than h = {scene['h']:g}, and the mesh "
                   "takes the smaller: the contact zone is meshed at h (give h_contact below h to refine it)")
    return (out + _locking(scene, model, g) + _contact_zone(scene, g) + _held_apex(scene, g)
            + _quadrature_cost(scene, model) + _kernel_fit(scene, model) + _unused(scene) + _underived(scene) + _ignored_by_the_solver(scene, used or {}))


def _locking(scene, model, g) -> list:
    """P1 near incompressibility (nu > 0.45 in 3D or plane strain; plane stress does not constrain the volume) locks:
    the tp4 slab in plane strain had 19 % of P2's tip displacement at nu = 0.49 and 1.5 % at 0.4999 (found by an
    outside pass, which the bending warning above did not cover)."""
    nu = scene.values.get("nu")
    if g.dim < 2 or scene["order"] != 1 or nu is None or nu <= 0.45 or "elastic_tensor" in scene.set_by_user:
        return []
    if g.dim == 2 and scene.values.get("plane", "stress") != "strain":
        return []
    remedy = "order = 2 locks far less" if model.max_order(g.dim) >= 2 else \
        "this model's 3D bodies are P1 only: refine h, and expect a stiff answer"
    return [f"{scene.name}: P1 elements lock near incompressibility (nu = {nu:g}"
            f"{', plane strain' if g.dim == 2 else ''}): displacements come out too small (the tp4 slab in plane "
            f"strain: 19 % of P2's tip displacement at nu = 0.49, 1.5 % at 0.4999); {remedy}"]


def _ignored_by_the_solver(scene, used: dict) -> list:
    """A value the user gave that the contact solver ``auto`` took does not read: ``contact_tol`` where it took the
    condensed solver, which solves each active set exactly (``contact_solver = 'condensed'`` with it is refused
    before the run; ``auto`` decides by the contact points, known once the mesh is made), or reads only if the zone
    outgrows the candidate points it solves on first, exactly too. ``used``: the scheme's :meth:`preflight`
    record."""
    if "contact_tol" not in scene.set_by_user:
        return []
    if used.get("contact_solver_used") == "condensed":
        return [f"{scene.name}: contact_tol = {scene['contact_tol']:g} has no effect: contact_solver = "
                f"{scene['contact_solver']!r} took the condensed solver here, which solves each active set exactly "
                "(contact_solver = 'coupled' takes the tolerance)"]
    if used.get("contact_candidates_planned"):  # (the coupled solver acts only if the zone outgrows them)
        return [f"{scene.name}: contact_tol = {scene['contact_tol']:g} acts only if the contact zone outgrows the "
                f"{used['contact_candidates_planned']} candidate points of smallest gap, on which contact_solver = "
                f"{scene['contact_solver']!r} solves each active set exactly first (contact_solver = 'coupled' "
                "takes the tolerance throughout)"]
    return []


#: Parameters that act only with another: (the parameters, whether that other acts, what it is).
_ONLY_WITH = ((CONTROL[1:], lambda v: is_adaptive(v["rtol"]), "rtol > 0 (error-controlled steps)"),
              (("gamma_nu", "eps_a", "L", "beta0", "c_tau", "bonding_truncation"), lambda v: v.get("adhesion", False),
               "adhesion = true"),
              (tuple(n for n in ADAPT if n not in ("space_tol", "edge_tol")),  # (edge_tol: refused alone)
               lambda v: v.get("space_tol", 0.0) > 0, "space_tol > 0 (adaptive meshes)"),
              (("contact_solver", "contact_tol"), lambda v: v.get("contact", True) or v.get("adhesion", False),
               "contact or adhesion (nothing acts on the contact side)"))


def _unused(scene) -> list:
    """A value the user gave that has no effect (it acts only with another that is off: k_max without rtol, gamma_nu
    without adhesion), which was ignored without a word."""
    out = []
    for names, acts, what in _ONLY_WITH:
        given = [name for name in names if name in scene.set_by_user and name in scene.values]
        if given and not acts(scene.values):
            out.append(f"{scene.name}: {', '.join(f'{n} = {scene[n]}' for n in given)} "
                       f"{'has' if len(given) == 1 else 'have'} no effect without {what}")
    return out


def _underived(scene) -> list:
    """A preset's own parameter that only makes values the user gave as well (tp3's omega with a delta given, the
    Hertz scenes' tau with a1 and a2 given), which was ignored without a word."""
    from ..input.scenes import PRESETS

    preset = PRESETS.get(scene.base)
    derived = set(preset.derive(scene.values)) if preset is not None and preset.derive is not None else set()
    # (a viscosity given as a1 or a2 stands over the viscous tensor a given elastic_tensor would make: scenes.make)
    covered = scene.set_by_user | ({"viscous_tensor"} if {"a1", "a2"} & scene.set_by_user else set())
    if not derived or not derived <= covered:
        return []
    made = ", ".join(sorted(derived))
    instead = ", ".join(sorted(derived & scene.set_by_user) or sorted({"a1", "a2"} & scene.set_by_user))
    return [f"{scene.name}: {n} = {scene[n]} has no effect with {instead} given (it only makes the preset's {made})"
            for n in preset.extras if n in scene.set_by_user]


#: Seconds per (step x stored step x displacement dof) of the quadrature memory (the rod, ndof 21: 10 s for 1e4
#: steps, 25 s for 2e4, on the 2-core machine of the project).
QUADRATURE_COST = 3e-9
#: Steps of the quadrature memory beyond which its O(n^2) cost is said.
QUADRATURE_STEPS = 20000


def _kernel_fit(scene, model) -> list:
    """A kernel that sums of exponentials do not fit within kernel_tol (cos(20 t): 6.7e-2 with 32 terms, against
    1e-6 asked): the run then has the fitted sum's memory, which the archive's kernel_fit_error recorded without a
    word."""
    fit = model.memory.fit if model.memory is not None else None
    if not fit or fit["error"] <= fit["tol"]:
        return []
    return [f"{scene.name}: kernel_approximation = 'exponentials' fits the kernel to {fit['error']:.2g} of its largest "
            f"value with {fit['terms']} terms on [0, {fit['T']:g}] s, not to kernel_tol = {fit['tol']:g}: the memory is "
            "that of the fitted sum; kernel_approximation = 'quadrature' integrates the kernel itself"]


def _quadrature_cost(scene, model) -> list:
    """A general kernel integrated by quadrature works over every stored step at each step: O(n^2) in the steps.
    Beyond :data:`QUADRATURE_STEPS`, the expected time and the O(1)-per-step alternative are said."""
    memory = model.memory
    if memory is None or memory.kind != "kernel":
        return []
    n = scene["T"] / scene["k"]
    if n <= QUADRATURE_STEPS:
        return []
    ndof = estimate(model.geometry, order=scene["order"]).ndof
    seconds = QUADRATURE_COST * n * n / 2 * ndof
    return [f"the kernel's memory by quadrature works over all stored steps at every step: {n:.3g} steps (T = "
            f"{scene['T']:g}, k = {scene['k']:g}) cost O(n^2), about {seconds / 60:.2g} min here; "
            "kernel_approximation = 'exponentials' (a sum of exponentials within kernel_tol) costs O(1) per step"]


def _held_apex(scene, g) -> list:
    """A Hertz body holds its apex at u_nu = 0 (the support against the rigid motion of a body pressed by a force,
    docs/choices.md): where the contact would move it (a gap, Model B's layer, a load that pulls), the hold carries
    a force instead, and the run is not that problem's (an outside pass, December 2026: with gap = 0.001 the apex
    held 19 % of the load while its neighbours crossed the gap; pulled by 5 N, it held the body alone)."""
    if not g.pins_contact or "load" not in scene.values:
        return []
    import numpy as np

    why = [f"{name} = {scene[name]:g}" for name in ("gap", "F", "c") if scene.values.get(name, 0.0) > 0]
    # (the load on a fine grid and beside its kinks: a pull of 1.2 ms between two ifpos switches fell between 201
    # samples, and the apex held it)
    load, T = scene["load"], scene["T"]
    times = np.concatenate([np.linspace(0.0, T, 2001)] + [[s - 1e-9 * T, s + 1e-9 * T] for s in load.kinks(T)])
    least = min(float(load(t=t)) for t in times)
    why += [f"load = {scene['load']} pulls (down to {least:g} N)"] if least < 0 else []
    if not why:
        return []
    return [f"{scene.name}: {', '.join(why)}: the apex is held at u_nu = 0 (the scene's support against the body's "
            "rigid motion), so that hold carries a force the contact would not (its reaction is the apex's "
            "contact_pressure) and the run is not that problem's; the Hertz scenes model a body pressed onto the "
            "foundation at zero gap: take a body from a mesh file for the others"]


def _contact_zone(scene, g) -> list:
    """Hertz's contact radius for the largest load near the edge of a Hertz body's contact zone (beyond it the side
    is free, so a contact reaching it is cut off)."""
    if g.zone_radius is None or "load" not in scene.values or "E" not in scene.values:
        return []
    import numpy as np

    from ..references import hertz

    P = max(float(scene["load"](t=t)) for t in np.linspace(0.0, scene["T"], 101))
    if P <= 0:
        return []
    a = (hertz.cylinder if g.dim == 2 else hertz.sphere)(P, g.extent[0], scene["E"], scene["nu"])[0]
    if a <= 0.8 * g.zone_radius:
        return []
    return [f"load = {P:g} gives Hertz's contact radius a = {a:.3g} m, near or beyond the contact zone (the part of "
            f"the curved side within {g.zone_radius:.3g} m of the apex, refined, that can touch the foundation): "
            "reduce the load, or increase contact_zone or radius"]
