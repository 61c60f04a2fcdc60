"""Safe expressions in x, y, z, t for loads and prescribed displacements.

The grammar (docs/conventions.md): numbers, the variables ``x y z t``, ``pi``, the operators
``+ - * / **`` (``^`` is read as ``**``), parentheses, the functions
``sin cos tan exp log sqrt abs`` and ``ifpos(a, b, c)`` (``b`` where ``a > 0``,
else ``c``). A vector is a parenthesised tuple ``(fx, fy)``. Text is parsed
with :mod:`ast` and walked against this whitelist: nothing is ``eval``-ed.

One parsed :class:`Expression` evaluates two ways: as an NGSolve coefficient
function of a time :class:`ngsolve.Parameter` (for forms), and with NumPy
(for references, checks and time-only data such as a rod's end displacement).

Examples
--------
>>> e = parse("(0, -sin(50*t))", name="traction_top")
>>> e.size
2
>>> float(e(t=0.0)[1])
-0.0
>>> parse("2*ifpos(x - 0.5, 1, 0)")(x=0.75)
2.0
"""
from __future__ import annotations

import ast
import copy
import difflib
import functools
import math
from dataclasses import dataclass, field

import numpy as np

VARIABLES = ("x", "y", "z", "t")
FUNCTIONS = ("sin", "cos", "tan", "exp", "log", "sqrt", "abs", "ifpos")
CONSTANTS = {"pi": math.pi}


class ExpressionError(ValueError):
    """A malformed expression; the message names the parameter and the fault."""


#: Limits that keep a mistyped or hostile expression from exhausting the parser or the machine.
MAX_LENGTH = 4000
MAX_DEPTH = 100


def _shown(text: str, n: int = 60) -> str:
    """The expression as quoted in a message (cut: a 60 kB text is not echoed back)."""
    return repr(text) if len(text) <= n else repr(text[: n - 3] + "...")


_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}


@dataclass(frozen=True)
class Expression:
    """A parsed scalar or vector expression.

    Attributes
    ----------
    source : str
        The text as given.
    terms : tuple of ast.AST
        One checked syntax tree per component.
    variables : frozenset of str
        Which of x, y, z, t occur.
    """

    source: str
    terms: tuple = field(repr=False)
    variables: frozenset = frozenset()

    @property
    def size(self) -> int:
        """Number of components (1 for a scalar)."""
        return len(self.terms)

    def depends_on(self, name: str) -> bool:
        return name in self.variables

    def is_zero(self) -> bool:
        """True when every component is the literal constant 0."""
        return all(isinstance(t, ast.Constant) and t.value == 0 for t in self.terms)

    def cf(self, t=0.0, coords=None):
        """NGSolve coefficient function(s); ``t`` may be a ``Parameter``.

        Returns a scalar CF for size 1, a vector CF otherwise. ``coords`` replaces
        the coordinates (default ``ngsolve.x, y, z``).
        """
        import ngsolve as ngs

        env = dict(zip(VARIABLES, coords or (ngs.x, ngs.y, ngs.z))) | {"t": t}
        funcs = {
            "sin": ngs.sin, "cos": ngs.cos, "tan": ngs.tan, "exp": ngs.exp,
            "log": ngs.log, "sqrt": ngs.sqrt,
            "abs": lambda a: ngs.IfPos(a, a, -a),
            "ifpos": ngs.IfPos,
        }
        parts = [_walk(term, env, funcs, ngs.CoefficientFunction) for term in self.terms]
        return parts[0] if len(parts) == 1 else ngs.CoefficientFunction(tuple(parts))

    def __call__(self, x=0.0, y=0.0, z=0.0, t=0.0):
        """Evaluate with NumPy (broadcasting); a float for a constant scalar."""
        env = _NUMPY_NAMESPACE | {"x": x, "y": y, "z": z, "t": t}
        try:
            parts = [eval(code, env) for code in self._compiled]  # noqa: S307 (checked trees, no builtins)
        except (ZeroDivisionError, OverflowError):
            # (Python floats raise where NumPy's give inf or NaN, e.g. 1/(t - 0.5) at t = 0.5: evaluated again as
            # NumPy's, the value is not finite and the run stops there as at any other, its steps kept)
            env |= {name: np.float64(v) if np.ndim(v) == 0 else v for name, v in zip("xyzt", (x, y, z, t))}
            with np.errstate(all="ignore"):
                parts = [eval(code, env) for code in self._compiled]  # noqa: S307
        if len(parts) == 1:
            value = parts[0]
            return float(value) if np.ndim(value) == 0 else np.asarray(value, dtype=float)
        if all(np.ndim(p) == 0 for p in parts):  # a load's g(t) every step: no broadcasting to do
            return np.array([float(p) for p in parts])
        shape = np.broadcast(*parts).shape
        return np.stack([np.broadcast_to(np.asarray(p, dtype=float), shape) for p in parts])

    def __str__(self) -> str:
        return self.source

    def kinks(self, T: float, samples: int = 20001) -> list:
        """The times in (0, T) where the expression stops being smooth in t: the zeros of ``ifpos``'s condition and
        of ``abs``'s argument, where these depend on t alone (a ramp held from t = 0.3, ``ifpos(t - 0.3, 0.3, t)``:
        [0.3]). Sign changes on ``samples`` times, each then bisected to round-off; a zero the sign does not cross
        (a touch) is not found. Error control lands on them (:class:`~workbench.schemes.stepping.AdaptiveSteps`).

        >>> parse("-0.6*ifpos(t - 0.3, 0.3, t)").kinks(1.0)
        [0.3]
        >>> [round(k, 12) for k in parse("(0, abs(sin(pi*t)) + ifpos(x - 0.5, t, 0))").kinks(2.5)]
        [1.0, 2.0]
        """
        found = set()
        for term in self.terms:
            for node in ast.walk(term):
                if isinstance(node, ast.Call) and node.func.id in ("ifpos", "abs"):
                    argument = node.args[0]
                    if {n.id for n in ast.walk(argument) if isinstance(n, ast.Name)} <= {"t", "pi", *FUNCTIONS}:
                        found.update(_sign_changes(argument, T, samples))
        return sorted(found)

    def __getstate__(self):  # (pickled to study workers: code objects do not pickle; they are compiled again there)
        return {k: v for k, v in self.__dict__.items() if k != "_compiled"}

    def __setstate__(self, state):
        self.__dict__.update(state)

    @functools.cached_property
    def _compiled(self) -> list:
        """The checked trees compiled once, numbers as floats (what the tree walk :func:`_walk` computes, operation
        for operation): a load is evaluated every step, and walking the tree cost tp5 0.14 ms a step. Safe: the trees
        hold only numbers, the variables, pi, the operators and the allowed functions (:func:`_check`), and they run
        without builtins."""
        out = []
        for term in self.terms:
            tree = ast.fix_missing_locations(ast.Expression(body=_AsFloats().visit(copy.deepcopy(term))))
            out.append(compile(tree, "<expression>", "eval"))
        return out


class _AsFloats(ast.NodeTransformer):
    """Numbers as floats (as the tree walk reads them: 2**-1 is 0.5, not an int power)."""

    def visit_Constant(self, node):
        return ast.copy_location(ast.Constant(float(node.value)), node)


#: The names a compiled expression sees besides x, y, z, t.
_NUMPY_NAMESPACE = {
    "__builtins__": {}, "sin": np.sin, "cos": np.cos, "tan": np.tan, "exp": np.exp, "log": np.log, "sqrt": np.sqrt,
    "abs": np.abs, "ifpos": lambda a, b, c: np.where(np.asarray(a) > 0, b, c),
    **{name: float(value) for name, value in CONSTANTS.items()},
}


def _sign_changes(node, T: float, samples: int) -> list:
    """The times in (0, T) where the tree ``node`` (of t alone) changes sign, bisected to round-off."""
    code = compile(ast.fix_missing_locations(ast.Expression(body=_AsFloats().visit(copy.deepcopy(node)))),
                   "<kink>", "eval")

    def value(t):
        with np.errstate(all="ignore"):
            return eval(code, _NUMPY_NAMESPACE | {"t": t})  # noqa: S307 (a checked tree, no builtins)

    t = np.linspace(0.0, T, samples)
    v = np.broadcast_to(np.asarray(value(t), dtype=float), t.shape)
    out = []
    for i in np.nonzero(np.isfinite(v[:-1]) & np.isfinite(v[1:]) & (np.sign(v[:-1]) * np.sign(v[1:]) < 0))[0]:
        lo, hi = float(t[i]), float(t[i + 1])
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if mid in (lo, hi):
                break
            lo, hi = (mid, hi) if np.sign(value(mid)) == np.sign(value(lo)) else (lo, mid)
        out.append(hi if abs(float(value(hi))) <= abs(float(value(lo))) else lo)
    zeros = t[1:-1][v[1:-1] == 0.0]  # (a sample on the zero itself, where the sign changes across it)
    out += [float(z) for z in zeros if np.sign(value(z - 1e-9 * T)) * np.sign(value(z + 1e-9 * T)) < 0]
    return [k for k in out if 0.0 < k < T]


def _walk(node, env, funcs, const):
    if isinstance(node, ast.Constant):
        return const(node.value)
    if isinstance(node, ast.Name):
        if node.id in CONSTANTS:
            return const(CONSTANTS[node.id])
        return env[node.id]
    if isinstance(node, ast.UnaryOp):
        operand = _walk(node.operand, env, funcs, const)
        return -operand if isinstance(node.op, ast.USub) else operand
    if isinstance(node, ast.BinOp):
        a = _walk(node.left, env, funcs, const)
        b = _walk(node.right, env, funcs, const)
        op = _BINOPS[type(node.op)]
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        if op == "*":
            return a * b
        if op == "/":
            return a / b
        return a**b
    if isinstance(node, ast.Call):
        args = [_walk(a, env, funcs, const) for a in node.args]
        return funcs[node.func.id](*args)
    raise AssertionError(f"unchecked node {type(node).__name__}")  # _check rejects these


#: A sum (or product) of more terms than this is regrouped as a balanced tree: ``a + b + c + ...`` is a left-deep
#: chain as Python parses it, and a load written as a sum of 120 terms was refused as "nested 120 levels deep".
LONG_CHAIN = 32


def _balanced(node):
    """``node`` with every long chain of + and - (or of *) regrouped as a balanced tree of depth log2(terms), walked
    without recursion down the chain (a short chain stays as written, so its rounding does not change)."""
    if not isinstance(node, ast.BinOp):
        if isinstance(node, (ast.UnaryOp, ast.Call)):
            for field in ("operand",) if isinstance(node, ast.UnaryOp) else ():
                setattr(node, field, _balanced(getattr(node, field)))
            if isinstance(node, ast.Call):
                node.args = [_balanced(a) for a in node.args]
        return node
    kinds = (ast.Add, ast.Sub) if isinstance(node.op, (ast.Add, ast.Sub)) else (type(node.op),)
    parts, cur = [], node
    while isinstance(cur, ast.BinOp) and isinstance(cur.op, kinds) and isinstance(cur.op, (ast.Add, ast.Sub, ast.Mult)):
        parts.append((isinstance(cur.op, ast.Sub), cur.right))
        cur = cur.left
    parts.append((False, cur))
    if len(parts) <= LONG_CHAIN:
        node.left, node.right = _balanced(node.left), _balanced(node.right)
        return node
    items = [ast.UnaryOp(op=ast.USub(), operand=_balanced(t)) if negative else _balanced(t)
             for negative, t in reversed(parts)]
    op = ast.Mult if isinstance(node.op, ast.Mult) else ast.Add
    while len(items) > 1:
        items = [ast.BinOp(left=items[i], op=op(), right=items[i + 1]) if i + 1 < len(items) else items[i]
                 for i in range(0, len(items), 2)]
    return ast.copy_location(items[0], node)


def _check(node, text, name, allowed, depth=0):
    """Reject anything outside the grammar, naming the parameter and the token."""
    where = f"in {name} = {_shown(text)}" if name else f"in {_shown(text)}"
    if depth > MAX_DEPTH:
        raise ExpressionError(f"{where}: nested more than {MAX_DEPTH} levels deep")
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            raise ExpressionError(f"{where}: only numbers are allowed as constants, got {str(node.value)[:40]!r}")
        try:
            finite = math.isfinite(float(node.value))
        except OverflowError:
            finite = False
        if not finite:
            raise ExpressionError(f"{where}: a constant is too large (not a finite float)")
        return
    if isinstance(node, ast.Name):
        if node.id in CONSTANTS or node.id in allowed:
            return
        known = list(allowed) + list(CONSTANTS)
        hint = difflib.get_close_matches(node.id, known + list(FUNCTIONS), n=1)
        extra = f"; did you mean {hint[0]!r}?" if hint else ""
        raise ExpressionError(
            f"{where}: unknown name {node.id!r} (allowed variables: {', '.join(allowed)}, constant: pi){extra}")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        _check(node.operand, text, name, allowed, depth + 1)
        return
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        _check(node.left, text, name, allowed, depth + 1)
        _check(node.right, text, name, allowed, depth + 1)
        return
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            fname = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            hint = difflib.get_close_matches(fname, FUNCTIONS, n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise ExpressionError(
                f"{where}: unknown function {fname!r} (allowed: {', '.join(FUNCTIONS)}){extra}")
        want = 3 if node.func.id == "ifpos" else 1
        if node.keywords or len(node.args) != want:
            raise ExpressionError(f"{where}: {node.func.id}() takes {want} argument(s)")
        for a in node.args:
            _check(a, text, name, allowed, depth + 1)
        return
    raise ExpressionError(f"{where}: {type(node).__name__} is not allowed in an expression")


def parse(text, *, name: str = "", allowed=VARIABLES, size: int | None = None) -> Expression:
    """Parse ``text`` (a string, a number, or a tuple/list of them) into an :class:`Expression`.

    Parameters
    ----------
    text : str, float or sequence
        The expression. Numbers and sequences of numbers/strings are accepted as is.
    name : str
        Parameter name, used in error messages.
    allowed : sequence of str
        Variables the expression may use (e.g. only ``("t",)`` for a rod-end displacement).
    size : int, optional
        Required number of components; a scalar 0 is broadcast to a zero vector.

    Raises
    ------
    ExpressionError
        On any syntax outside the grammar, an unknown name, or a wrong size.
    """
    expr = text if isinstance(text, Expression) else _parse_source(_source(text, name), name, allowed)
    bad = [v for v in expr.variables if v not in allowed]
    if bad:
        raise ExpressionError(f"in {name} = {_shown(expr.source)}: {bad[0]!r} not allowed here (allowed: "
                              f"{', '.join(allowed)})")
    if size is not None and expr.size != size:
        if expr.size == 1 and expr.is_zero() and "," not in expr.source:  # (a plain 0 is the zero vector; (0,) not)
            return Expression(expr.source, expr.terms * size, expr.variables)
        raise ExpressionError(
            f"{name} = {_shown(expr.source)} has {expr.size} component(s), {size} are needed"
            + (f", e.g. '({', '.join(['0'] * size)})'" if size > 1 else ""))
    return expr


def _source(text, name) -> str:
    """The text of an expression given as text, a number, or a tuple/list of them (a vector)."""
    if isinstance(text, (list, tuple)):
        return "(" + ", ".join(str(_as_text(v, name)) for v in text) + ")"
    return str(_as_text(text, name))


def _parse_source(source, name, allowed) -> Expression:
    """The :class:`Expression` of ``source``: parsed with :mod:`ast` (within the size and depth limits) and every
    component checked against the grammar."""
    src = source.replace("^", "**").strip()
    if not src:
        raise ExpressionError(f"{name or 'expression'} is empty")
    if len(src) > MAX_LENGTH:
        raise ExpressionError(f"{name} = {_shown(source)} is {len(src)} characters long; at most {MAX_LENGTH} "
                              "are allowed")
    if src.count("(") > MAX_DEPTH * 4:
        raise ExpressionError(f"in {name} = {_shown(source)}: too many parentheses (nesting is limited to "
                              f"{MAX_DEPTH} levels)")
    try:
        tree = ast.parse(src, mode="eval").body
    except SyntaxError as err:
        raise ExpressionError(f"in {name} = {_shown(source)}: syntax error ({err.msg})") from None
    except (RecursionError, MemoryError):
        raise ExpressionError(f"in {name} = {_shown(source)}: nested too deeply (at most {MAX_DEPTH} "
                              "levels)") from None
    terms = tuple(tree.elts) if isinstance(tree, ast.Tuple) else (tree,)
    if not terms:
        raise ExpressionError(f"in {name} = {_shown(source)}: empty tuple")
    try:  # (a chain of 1300 divisions or unary minuses recursed past Python's limit here: a traceback)
        terms = tuple(_balanced(term) for term in terms)
        for term in terms:
            _check(term, source, name, allowed)
    except RecursionError:
        raise ExpressionError(f"in {name} = {_shown(source)}: nested too deeply (at most {MAX_DEPTH} "
                              "levels)") from None
    used = frozenset(n.id for term in terms for n in ast.walk(term)
                     if isinstance(n, ast.Name) and n.id in VARIABLES)
    return Expression(source, terms, used)


def _as_text(value, name):
    if isinstance(value, bool):
        raise ExpressionError(f"{name}: expected an expression, got {value!r}")
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise ExpressionError(f"{name} = {value!r} is not finite")
        return repr(float(value))
    if isinstance(value, str):
        return value
    raise ExpressionError(f"{name}: expected an expression (text or number), got {type(value).__name__}")
