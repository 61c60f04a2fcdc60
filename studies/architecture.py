"""The run core's structure figures, measured from the package's source alone (an AST walk; nothing is run).

    python studies/architecture.py            # the table
    python studies/architecture.py --details  # and where each counted item stands (file:line)

Figures (the table of issue 21):

* import cycles: strongly connected components of the import graph between the package's modules, counting every
  import (module level, inside functions, ``importlib.import_module`` with a literal name); a package and its own
  submodule importing each other is not counted;
* modules besides ``parallel`` (and its own submodules) that import it or mpi4py;
* string switches on the model kind (``.kind == "B"``, ``.model == "A"``, ...);
* the largest class and function (lines, decorators excluded);
* literal lists of numerical-option names defined at module or class level (a definition of which parameters are
  numerics): a tuple, list, set or frozenset of at least two string constants, all of them names of numerical options
  (``k``, ``scheme``, ``rtol``, ...), outside ``numerics`` where the one list lives;
* "adaptive iff rtol > 0" written: comparisons of an ``rtol`` against 0;
* ``getattr``/``hasattr`` with a literal attribute name on an object (protocol probes); calls on the command line's
  argparse namespace (``args``), in a module's ``__getattr__`` and on a module object are not probes;
* arrows that run back up the layers: an import from a package of a lower layer into one of a higher layer
  (:data:`LAYERS`, top first).
"""
from __future__ import annotations

import ast
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "workbench"
PACKAGE = "workbench"

#: The numerical options (what is discretisation, not physics): a literal collection made only of these names is a
#: copy of the list that ``workbench.numerics`` holds.
NUMERICAL_NAMES = {"h", "k", "T", "order", "scheme", "solver", "rtol", "atol", "k_min", "k_max", "allow_unstable",
                   "memory_rule", "kernel_approximation", "kernel_tol", "nx", "ny", "nz", "h_contact", "threads",
                   "checkpoint_every", "snapshots", "probes"}

#: The layers, top first: a module may import from its own layer and the ones below it. A name is a subpackage or a
#: module of the package (its first component after ``workbench``).
LAYERS = [
    ("command line", {"cli", "__main__"}),
    ("paper", {"paper"}),
    ("study and plots", {"study", "plotting"}),
    ("running", {"running", "runner", "restart", "parallel", "preflight"}),
    ("output", {"output", "results", "vtk", "files"}),
    ("schemes", {"schemes"}),
    ("discretisation", {"discrete", "discretisation", "boundary", "condensation", "solvers", "stability", "eigen",
                        "transfer", "world"}),
    ("scene input", {"input", "scenes", "geometry", "meshes", "models", "numerics", "parameters"}),
    ("references", {"references"}),
    ("physics", {"physics"}),
    ("base", {"values", "expressions", "errors", "threads", "__init__"}),
]


def modules(root: Path) -> dict:
    out = {}
    for f in sorted(root.rglob("*.py")):
        parts = f.relative_to(root.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def _resolve(current: str, is_package: bool, level: int, module: str | None) -> str:
    if level == 0:
        return module or ""
    base = current.split(".") if is_package else current.split(".")[:-1]
    base = base[: len(base) - (level - 1)] if level > 1 else base
    return ".".join(base + ([module] if module else []))


def _target(name: str, mods: dict) -> str | None:
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def imports(mods: dict) -> dict:
    """module -> {(imported module, line)} over every import in it."""
    edges = {}
    for name, f in mods.items():
        tree = ast.parse(f.read_text())
        is_package = f.name == "__init__.py"
        out = edges.setdefault(name, set())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                m = _resolve(name, is_package, node.level, node.module)
                names = [m] + [f"{m}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == \
                    "import_module" and node.args and isinstance(node.args[0], ast.Constant) \
                    and isinstance(node.args[0].value, str):
                a = node.args[0].value
                if a.startswith("."):
                    level = len(a) - len(a.lstrip("."))
                    a = _resolve(name, is_package, level, a.lstrip(".") or None)
                names = [a]
            for n in names:
                if n.split(".")[0] == "mpi4py":
                    out.add(("mpi4py", node.lineno))
                t = _target(n, mods) if n.split(".")[0] == PACKAGE else None
                if t and t != name:
                    out.add((t, node.lineno))
    return edges


def cycles(edges: dict) -> list:
    """Strongly connected components (Tarjan) of more than one module, but a package with its own submodule."""
    graph = {v: {t for t, _ in e if t != "mpi4py"} for v, e in edges.items()}
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(graph):
        if v not in index:
            strong(v)
    return [c for c in out if not (len(c) == 2 and c[1].startswith(c[0] + "."))]


def _layer(module: str) -> int | None:
    parts = module.split(".")
    first = parts[1] if len(parts) > 1 else "__init__"
    for i, (_, names) in enumerate(LAYERS):
        if first in names:
            return i
    return None


def measure(root: Path = ROOT) -> dict:
    mods = modules(root)
    edges = imports(mods)
    parallel = f"{PACKAGE}.parallel"
    mpi_users = sorted({f"{m}:{line}" for m, e in edges.items() for t, line in e
                        if (t == "mpi4py" or t == parallel or t.startswith(parallel + "."))
                        and not (m == parallel or m.startswith(parallel + "."))})
    back = sorted(f"{m}:{line} -> {t}" for m, e in edges.items() for t, line in e if t != "mpi4py"
                  and _layer(m) is not None and _layer(t) is not None and _layer(t) < _layer(m))
    switches, lists, rtol, probes, classes, functions = [], [], [], [], [], []
    for name, f in mods.items():
        src = f.read_text()
        tree = ast.parse(src)
        for scope in [tree] + [n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)]:
            for statement in scope.body:
                if isinstance(statement, (ast.Assign, ast.AnnAssign)) and statement.value is not None:
                    for sub in ast.walk(statement.value):
                        sub._defined = True  # noqa: SLF001
        for i, line in enumerate(src.splitlines(), 1):
            if re.search(r"\.(kind|model)\s*[!=]=\s*['\"](A|B)['\"]", line):
                switches.append(f"{name}:{i}")
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                classes.append((node.end_lineno - node.lineno + 1, f"{name}.{node.name}"))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                functions.append((node.end_lineno - node.lineno + 1, f"{name}.{node.name}"))
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)) and not name.endswith(".numerics") \
                    and getattr(node, "_defined", False):
                strings = [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
                if len(strings) >= 2 and len(strings) == len(node.elts) and set(strings) <= NUMERICAL_NAMES \
                        and len(set(strings) & {"k", "rtol", "scheme", "atol", "k_min", "k_max", "solver"}) >= 2:
                    lists.append(f"{name}:{node.lineno} {strings}")
            if isinstance(node, ast.Compare) and len(node.ops) == 1 and isinstance(node.ops[0], (ast.Gt, ast.GtE)) \
                    and isinstance(node.comparators[0], ast.Constant) and node.comparators[0].value == 0 \
                    and "rtol" in ast.unparse(node.left):
                rtol.append(f"{name}:{node.lineno} {ast.unparse(node)}")
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef) and node.name == "__getattr__":
                for sub in ast.walk(node):
                    sub._in_module_getattr = True  # noqa: SLF001
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                    and node.func.id in ("getattr", "hasattr") and len(node.args) >= 2 \
                    and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str) \
                    and not getattr(node, "_in_module_getattr", False):
                receiver = ast.unparse(node.args[0])
                if receiver in ("args",) or receiver.startswith(("importlib", "plotting", "md.")):
                    continue
                probes.append(f"{name}:{node.lineno} {ast.unparse(node)}")
    classes.sort(reverse=True)
    functions.sort(reverse=True)
    return {"modules": len(mods), "import_cycles": cycles(edges), "mpi_aware_modules": mpi_users,
            "kind_switches": switches, "largest_class": classes[0], "largest_function": functions[0],
            "numerics_name_lists": lists, "rtol_positive_tests": rtol, "probes": probes, "back_arrows": back,
            "classes_over_250": [c for c in classes if c[0] > 250],
            "functions_over_60": [f for f in functions if f[0] > 60]}


def table(m: dict) -> str:
    mpi_modules = sorted({s.split(":")[0] for s in m["mpi_aware_modules"]})
    rows = [
        ("import cycles", len(m["import_cycles"]), "0"),
        ("modules besides parallel that import it or mpi4py", len(mpi_modules), "<= 2"),
        ("string switches on the model kind", len(m["kind_switches"]), "0"),
        ("largest class (lines)", f"{m['largest_class'][0]} ({m['largest_class'][1]})", "<= 250"),
        ("largest function (lines)", f"{m['largest_function'][0]} ({m['largest_function'][1]})", "<= 60"),
        ("literal lists of numerical options outside numerics", len(m["numerics_name_lists"]), "0 (1: numerics)"),
        ("'rtol > 0' written", len(m["rtol_positive_tests"]), "1"),
        ("getattr/hasattr probes", len(m["probes"]), "0"),
        ("imports that run back up the layers", len(m["back_arrows"]), "0"),
    ]
    w = max(len(r[0]) for r in rows)
    lines = [f"{'figure':<{w}}  {'now':<52}  goal"]
    lines += [f"{a:<{w}}  {str(b):<52}  {c}" for a, b, c in rows]
    return "\n".join(lines)


if __name__ == "__main__":
    figures = measure()
    print(table(figures))
    if "--details" in sys.argv:
        print(json.dumps({k: v for k, v in figures.items() if k != "modules"}, indent=1))
