"""Hyperparameter constraints: one table per method, checked in one place.

scikit-learn's ``_parameter_constraints`` idea, small enough to write here (its
``sklearn.utils._param_validation`` is private API, lets ``inf`` into open-ended intervals
and takes ``True`` for an int, which a hyperparameter reaching torch must not be).

A method declares :attr:`~imuloco.methods.base.Method.param_constraints`: for a parameter,
an interval (``"[1, inf)"``, ``"(0, 1]"``; of a list-valued one, of each of its at least one
items) or an :class:`Options` of the values it takes. Its kind comes from its default (a bool,
an int, a float, a string, a tuple of ints or floats) or, for a default of None, from its
annotation (``int | None``), so the table states only what the signature cannot. A check of
several parameters together (tautges2008's ``hop <= window``) is the method's
:meth:`~imuloco.methods.base.Method.check_together`.

:func:`check_params` runs when a method is constructed (before its ``__init__``, which only
stores), when it is fitted (``set_params`` may have changed it) and so when a model file is
loaded (:mod:`imuloco.methods.modelfile` names the file and the header's field).
"""

from __future__ import annotations

import inspect
import math
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

import numpy as np

from imuloco.errors import ParameterError


@dataclass(frozen=True)
class Options:
    """The values a string hyperparameter takes, e.g. ``Options("world", "sensor")``."""

    values: tuple[Any, ...]

    def __init__(self, *values: Any) -> None:
        object.__setattr__(self, "values", values)


Constraint = str | Options

# what a hyperparameter's value may be, and how an error names it; "ints" and "floats" are
# lists of them (a tuple default, e.g. hidden=(32,), periods=(0.8, 1.0))
KIND_NAMES = {bool: "true or false", int: "a whole number", float: "a finite number",
              str: "a string", type(None): "None", "ints": "a list of whole numbers",
              "floats": "a list of finite numbers"}


def kinds(default: Any, hint: Any) -> tuple:
    """The kinds of :data:`KIND_NAMES` a parameter takes: its default's (bool before int, a
    bool being an int), or for a default of None its annotation's (``int | None``); none to
    check when either is another type."""
    if default is None:
        union = typing.get_origin(hint) in (typing.Union, types.UnionType)
        found = typing.get_args(hint) if union else (hint,)
        return found if all(k in KIND_NAMES for k in found) else ()
    if isinstance(default, tuple) and default:
        return ("ints" if all(fits(d, int) for d in default) else "floats",)
    return next(((k,) for k in (bool, int, float, str) if isinstance(default, k)), ())


def fits(value: Any, kind: Any) -> bool:
    """Whether ``value`` is of ``kind`` (:data:`KIND_NAMES`). Numbers must be finite (NaN and
    inf pass every range check) and never a bool; an int is a float too."""
    if kind in ("ints", "floats"):
        return isinstance(value, (list, tuple)) and all(
            fits(v, int if kind == "ints" else float) for v in value)
    flag = isinstance(value, (bool, np.bool_))
    if kind is bool:
        return flag
    if kind in (int, float):  # an int is finite however large (isfinite would overflow)
        return not flag and (isinstance(value, Integral) or kind is float
                             and isinstance(value, Real) and math.isfinite(value))
    return value is None if kind is type(None) else isinstance(value, kind)


def within(value: Any, interval: str) -> bool:
    """Whether the number ``value`` lies in ``interval``, written ``[low, high)`` and the like
    (``inf`` for no bound); NaN lies in none."""
    low, high = (float(x) for x in interval[1:-1].split(","))
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        return False
    return ((low <= v if interval[0] == "[" else low < v)
            and (v <= high if interval[-1] == "]" else v < high))


def _show(value: Any) -> str:
    """``repr(value)``, cut to 60 characters (a 400-digit number, a long list)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _hints(function) -> dict[str, Any]:
    """``function``'s resolved annotations; none when they cannot be resolved."""
    try:
        return typing.get_type_hints(function)
    except (NameError, TypeError):
        return {}


def bind(cls: type, name: str, args: tuple, kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """The hyperparameters a call ``cls(*args, **kwargs)`` gives, defaults filled in;
    :class:`ParameterError` for a name the constructor does not take."""
    sig = inspect.signature(cls.__init__)
    takes_any = any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values())
    named = [k for k, p in sig.parameters.items()
             if k != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    for key in kwargs:
        if key not in named and not takes_any:
            raise ParameterError(key, f"method {name!r} has no parameter {key!r}; it takes "
                                      f"{named}")
    try:
        bound = sig.bind(None, *args, **kwargs)
    except TypeError as e:
        raise ParameterError("", f"method {name!r}: {e}") from None
    bound.apply_defaults()
    return {k: v for k, v in bound.arguments.items() if k in named}


def check_params(cls: type, name: str, params: Mapping[str, Any]) -> None:
    """Raise :class:`ParameterError` naming the first of ``params`` (hyperparameters of
    method class ``cls``, called ``name`` in messages) that is not of its kind, outside its
    interval or not one of its options (``cls.param_constraints``)."""
    sig = inspect.signature(cls.__init__)
    hints = _hints(cls.__init__)
    table: Mapping[str, Constraint] = getattr(cls, "param_constraints", {})
    for key, value in params.items():
        p = sig.parameters.get(key)
        found = kinds(p.default, hints.get(key)) if p is not None else ()
        if found and not any(fits(value, k) for k in found):
            expected = " or ".join(KIND_NAMES[k] for k in found)
            raise ParameterError(key, f"method {name!r}: parameter {key!r} expects {expected}, "
                                      f"got {_show(value)}")
        rule = table.get(key)
        if rule is None or value is None:  # an optional one left out (a rank: the fit's)
            continue
        if isinstance(rule, Options):
            if value not in rule.values:
                raise ParameterError(key, f"method {name!r}: unknown {key} {value!r}; {key} "
                                          f"must be one of {', '.join(map(str, rule.values))}")
            continue
        items = list(value) if isinstance(value, (list, tuple)) else [value]
        if not items or not all(within(v, rule) for v in items):
            what = "items" if isinstance(value, (list, tuple)) else "value"
            raise ParameterError(key, f"method {name!r}: parameter {key!r} expects {what} in "
                                      f"{rule}, got {_show(value)}")
