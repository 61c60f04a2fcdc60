"""A parameter's definition, and how a value given as text, TOML or Python is coerced and checked.

:class:`Param` is one row of the parameter table (:mod:`workbench.input.parameters`): name, default, unit, meaning,
kind and allowed range. A contact law declares the rows it adds with it (:mod:`workbench.physics.laws`), so this
module sits below the physics and knows nothing of scenes.

Examples
--------
>>> Param("nu", 0.3, "1", "Poisson's ratio", lower=-1.0, upper=0.5, lower_open=True, upper_open=True).check("0.25")
0.25
"""
from __future__ import annotations

import difflib
import json
import math
import numbers
import os
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError
from .expressions import Expression, ExpressionError, parse


@dataclass(frozen=True)
class Param:
    """One parameter.

    ``kind`` is one of ``float``, ``int``, ``flag``, ``choice``, ``expr``
    (scalar expression), ``vector`` (vector expression, size set by the
    geometry), ``points`` (a list of coordinate tuples), ``times`` (a list of
    times) or ``matrix`` (a square matrix of numbers, empty when not given). ``lower``/``upper`` bound numbers; ``*_open`` says whether the bound
    itself is excluded.
    """

    name: str
    default: object
    unit: str
    meaning: str
    kind: str = "float"
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    upper_open: bool = False
    choices: tuple = ()
    variables: tuple = ("x", "y", "z", "t")

    def range_text(self) -> str:
        """The allowed range in words, for messages and ``workbench show``."""
        if self.kind == "choice":
            return " | ".join(repr(c) for c in self.choices)
        if self.kind == "flag":
            return "true | false"
        if self.kind in ("expr", "vector"):
            return "expression in " + ", ".join(self.variables)
        if self.kind == "text":
            return "text"
        if self.kind == "mapping":
            return "a table name = role"
        if self.lower is None and self.upper is None:
            return "any finite number" if self.kind in ("float", "int") else ""
        parts = []
        if self.lower is not None:
            parts.append(f"{_fmt(self.lower)} {'<' if self.lower_open else '<='}")
        parts.append(self.name)
        if self.upper is not None:
            parts.append(f"{'<' if self.upper_open else '<='} {_fmt(self.upper)}")
        return " ".join(parts)

    def check(self, value, size: int | None = None):
        """Coerce ``value`` to this parameter's kind and check its range."""
        name = self.name
        if self.kind in ("float", "int"):
            return self._number(value)
        if self.kind == "flag":
            return _flag(name, value)
        if self.kind == "choice":
            if value in self.choices:
                return value
            hint = difflib.get_close_matches(str(value), [str(c) for c in self.choices], n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise ParameterError(f"{name} = {value!r} is not allowed; choose one of {self.range_text()}{extra}")
        if self.kind in ("expr", "vector"):
            try:
                return parse(value, name=name, allowed=self.variables,
                             size=(1 if self.kind == "expr" else size))
            except ExpressionError as err:
                raise ParameterError(str(err)) from None
        if self.kind in ("points", "times", "matrix") and (value is None or str(value).strip().lower() in ("", "none")):
            return ()  # (the parameter table shows an empty default as "none": the same value typed back)
        if self.kind == "points":
            return _points(name, value)
        if self.kind == "times":
            return _times(name, value)
        if self.kind == "matrix":
            return _matrix(name, value)
        if self.kind == "text":
            if not isinstance(value, str):
                raise ParameterError(f"{name} = {value!r}: give text (a file path)")
            return value
        if self.kind == "mapping":
            return _mapping(name, value)
        raise AssertionError(self.kind)

    def _number(self, value):
        """A float or int parameter's value: text and NumPy scalars read as numbers, then checked finite, integral
        for an int, and within the bounds."""
        name = self.name
        if isinstance(value, str):
            try:
                value = float(value.strip())
            except ValueError:
                raise ParameterError(f"{name} = {value!r} is not a number") from None
        if isinstance(value, np.ndarray) and value.ndim == 0:  # (a NumPy scalar result)
            value = value.item()
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ParameterError(f"{name} = {value!r} is not a number")
        value = float(value)
        if not math.isfinite(value):
            raise ParameterError(f"{name} = {value} is not finite; allowed: {self.range_text()}")
        if self.kind == "int":
            if value != int(value):
                raise ParameterError(f"{name} = {value} must be an integer; allowed: {self.range_text()}")
            if abs(value) > INT_LIMIT:  # (an archive stores it as a 32-bit attribute; 1e308 steps is a slip)
                raise ParameterError(f"{name} = {_fmt(value)} is outside the allowed range {self.range_text()} "
                                     f"(and at most {INT_LIMIT})")
            value = int(value)
        lo, hi = self.lower, self.upper
        bad_lo = lo is not None and (value <= lo if self.lower_open else value < lo)
        bad_hi = hi is not None and (value >= hi if self.upper_open else value > hi)
        if bad_lo or bad_hi:
            raise ParameterError(f"{name} = {_fmt(value)} is outside the allowed range {self.range_text()}")
        return value


#: The largest integer parameter (the largest 32-bit integer: archives store integers so).
INT_LIMIT = 2**31 - 1


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _flag(name, value) -> bool:
    """A flag's value: a bool, 0 or 1, or text such as true/false, yes/no, on/off."""
    if isinstance(value, str):
        low = value.strip().lower()
        if low in ("1", "true", "yes", "on"):
            return True
        if low in ("0", "false", "no", "off"):
            return False
    elif isinstance(value, (bool, int)) and value in (0, 1):
        return bool(value)
    raise ParameterError(f"{name} = {value!r} is not a flag; allowed: true | false")


def _points(name, value):
    if isinstance(value, str):
        text = value.strip()
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            # "(1, 0.1); (0.5, 0)" on the command line
            try:
                value = [[float(c) for c in p.strip().strip("()[]").split(",") if c.strip()]
                         for p in text.split(";") if p.strip()]
            except ValueError:
                raise ParameterError(f"{name} = {text!r}: give tuples as '(a, b); (c, d)' or a JSON list, or none") \
                    from None
    try:
        pts = tuple(tuple(float(c) for c in (p if isinstance(p, (list, tuple, np.ndarray)) else [p])) for p in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {value!r}: expected a list of tuples of numbers, or none") from None
    if any(not math.isfinite(c) for p in pts for c in p):
        raise ParameterError(f"{name}: coordinates must be finite")
    return pts


def _times(name, value):
    if isinstance(value, str):  # "0.1, 0.2", or as `workbench show` prints a list: "[0.1, 0.2]"
        text = value.strip()
        if text[:1] in "[(" and text[-1:] in ")]":
            text = text[1:-1]
        if any(c in text for c in "[]()"):
            raise ParameterError(f"{name} = {value!r}: expected a flat list of times, e.g. [0.1, 0.2]")
        value = [v for v in text.replace(";", ",").split(",") if v.strip()]
    try:
        ts = tuple(float(v) for v in (value if isinstance(value, Iterable) else [value]))
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {value!r}: expected a list of times") from None
    if any(not math.isfinite(t) or t < 0 for t in ts):
        raise ParameterError(f"{name}: times must be finite and >= 0")
    return ts


def _matrix(name, value):
    if isinstance(value, str):
        text = value.strip()
        if not text:
            return ()
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            raise ParameterError(f"{name} = {text!r}: give a matrix as a JSON list of rows, e.g. "
                                 "[[1100, 330, 0], [330, 1100, 0], [0, 0, 385]]") from None
    try:
        rows = tuple(tuple(float(c) for c in row) for row in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {value!r}: expected a list of rows of numbers") from None
    if rows and (any(len(r) != len(rows) for r in rows) or any(not math.isfinite(c) for r in rows for c in r)):
        raise ParameterError(f"{name}: the matrix must be square with finite entries")
    return rows


def _mapping(name, value):
    """A mapping of names to text (the roles of a mesh's boundaries), sorted by name; JSON text is read too."""
    if isinstance(value, str):
        try:
            value = json.loads(value) if value.strip() else {}
        except json.JSONDecodeError:
            raise ParameterError(f"{name} = {value!r}: give a table of name = value, e.g. "
                                 '{"bottom": "contact", "left": "clamped"}') from None
    if isinstance(value, (list, tuple)):
        try:
            value = dict(value)
        except (TypeError, ValueError):
            raise ParameterError(f"{name} = {value!r}: expected a table of name = value") from None
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in value.items()):
        raise ParameterError(f"{name} = {value!r}: expected a table of names to text, e.g. "
                             '{"bottom": "contact", "left": "clamped"}')
    return dict(sorted(value.items()))


def closest_name(name: str, known) -> str:
    """A 'did you mean' suffix for an unknown name, or '' (an exact match but for case comes first)."""
    known = list(known)
    same = [k for k in known if k.lower() == str(name).lower()]
    hint = same or difflib.get_close_matches(str(name), known, n=1, cutoff=0.6)
    return f"; did you mean {hint[0]!r}?" if hint else ""


def to_plain(value):
    """A JSON-able form of a checked value (expressions become their text)."""
    if isinstance(value, Expression):
        return value.source
    if isinstance(value, tuple):
        return [to_plain(v) for v in value]
    return value


def check_threads(value, name: str):
    """``value`` (None: the default) as a thread count, or a ParameterError naming ``name`` and the range: 1 to four
    per core. More only wait, and each of NGSolve's threads reserves its own working memory: 256 on a 2-core
    machine with 23 GB ended in "Could not allocate localheap", a traceback after the setup (found by an outside
    pass)."""
    import os

    cores = os.cpu_count() or 1
    if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Integral)
                              or not 1 <= value <= 4 * cores):
        raise ParameterError(f"{name} {value!r}: give an integer from 1 to {4 * cores} (NGSolve TaskManager threads, "
                             f"at most four per core; this machine has {cores})")
    return value


def not_utf8(text: str):
    """``text`` with its bytes that are not UTF-8 escaped (as Python reads them from a name in another encoding:
    lone surrogates), or None where it is UTF-8.

    >>> not_utf8("Dämpfer"), not_utf8("D" + chr(0xDCE4) + "mpfer")
    (None, 'D\\\\udce4mpfer')
    """
    try:
        text.encode("utf-8")
        return None
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def check_utf8_path(path, what: str) -> None:
    """Refuse a path whose absolute form holds bytes that are not UTF-8 (a folder named in Latin-1 on an old system,
    a share, a zip file): netCDF takes its paths and attributes as UTF-8, so the run was done and its archive lost,
    the copy kept in the temporary folder too, since the scene file's path is one of its attributes (found by an
    outside pass). ``what`` names the option or parameter.

    >>> check_utf8_path("out/a.nc", "-o")
    >>> try:
    ...     check_utf8_path("M" + chr(0xDCE4) + "rz.nc", "-o")  # (the byte 0xe4 of a Latin-1 name, as Python reads it)
    ... except ParameterError as err:
    ...     print(str(err).split("': ")[1].split(' (')[0])
    its path holds bytes that are not UTF-8
    """
    shown = not_utf8(os.path.abspath(os.path.expanduser(str(path))))
    if shown is not None:
        raise ParameterError(f"{what} '{shown}': its path holds bytes that are not UTF-8 (a name made in another "
                             "encoding); netCDF takes UTF-8 paths only: rename the file or the folder it is "
                             "in") from None
