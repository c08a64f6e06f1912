"""Methods by name: the registry behind ``bench``, ``train``, ``reconstruct`` and ``live``.

Built-in methods are entry points of the group ``imuloco.methods`` in ``pyproject.toml``
(``name = "module:Class"``); a third-party package adds its own methods the same way, in its
own ``pyproject.toml``, and needs no change here. :func:`method_class` imports a method's
module on first use, so a command that needs ``ridge`` never imports torch. A class can also
be registered by hand with :func:`register` (tests, notebooks).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from importlib.metadata import EntryPoint, entry_points
from typing import TYPE_CHECKING, Any, TypeVar

from imuloco.errors import MissingExtraError, UnknownNameError

if TYPE_CHECKING:
    from imuloco.methods.base import Method

GROUP = "imuloco.methods"
REGISTRY: dict[str, type[Method]] = {}
M = TypeVar("M", bound="type[Method]")

# missing third-party module -> the extra of imuloco that installs it
_OPTIONAL = {"torch": "deep", "ahrs": "fusion"}


def register(cls: M) -> M:
    """Class decorator: make a method available under ``cls.name``."""
    if cls.name in REGISTRY and REGISTRY[cls.name] is not cls:
        raise ValueError(f"method name {cls.name!r} is registered twice")
    REGISTRY[cls.name] = cls
    return cls


def _entry_points() -> dict[str, EntryPoint]:
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def method_names() -> list[str]:
    """Names of every installed and registered method (their dependencies may be missing)."""
    return sorted(set(_entry_points()) | set(REGISTRY))


def method_class(name: str) -> type[Method]:
    """The class registered as ``name``, importing its module on first use.

    Raises :class:`UnknownNameError` for an unknown name, :class:`MissingExtraError` for a
    method whose optional dependency is missing."""
    if name not in REGISTRY:
        ep = _entry_points().get(name)
        if ep is None:
            raise UnknownNameError(f"unknown method {name!r}; available: {method_names()}")
        try:
            cls = ep.load()
        except ModuleNotFoundError as e:
            if e.name not in _OPTIONAL:
                raise
            raise MissingExtraError(f"method {name!r}", e.name, _OPTIONAL[e.name]) from None
        if getattr(cls, "name", None) != name:
            raise UnknownNameError(f"entry point {name!r} of group {GROUP!r} names "
                                   f"{ep.value}, whose name is {getattr(cls, 'name', None)!r}")
        REGISTRY.setdefault(name, cls)
    return REGISTRY[name]


def available_methods() -> dict[str, type[Method]]:
    """Every method whose dependencies are installed, by name (imports them all)."""
    out = {}
    for name in method_names():
        try:
            out[name] = method_class(name)
        except MissingExtraError:
            continue
    return out


def get_method(name: str, **params) -> Method:
    """A new, unfitted method by name."""
    return method_class(name)(**params)


def parse_params(items: Iterable[str], where: str = "parameter") -> dict[str, Any]:
    """``key=value`` strings -> a dict of hyperparameters; values parsed as JSON when they can
    be (numbers, ``true``, ``null``, lists), else kept as stripped strings.

    Raises :class:`UnknownNameError` naming ``where`` for an item without ``=``."""
    params: dict[str, Any] = {}
    for item in items:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise UnknownNameError(f"{where}: expected key=value, got {item!r}")
        try:
            params[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            params[key.strip()] = value.strip()
    return params


def parse_method_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"eom2014[variant=mlp-no-hmm;context=7]"`` -> ``("eom2014", {"variant": "mlp-no-hmm",
    "context": 7})``: a method name with hyperparameters (:func:`parse_params`). Lets one
    bench compare variants of a method (e.g. the 2014 paper's ablation)."""
    name, _, rest = spec.partition("[")
    if rest and not rest.endswith("]"):
        raise UnknownNameError(f"method {spec!r}: expected NAME[key=value;key=value]")
    return name.strip(), parse_params(filter(None, rest[:-1].split(";")), f"method {spec!r}")
