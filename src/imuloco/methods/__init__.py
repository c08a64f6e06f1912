"""Reconstruction methods behind one interface (:class:`imuloco.methods.base.Method`).

Methods are found by name: :func:`method_class` imports a built-in method's module on first
use (so a command that needs ``ridge`` never imports torch), :func:`get_method` builds one, and
:func:`available_methods` imports them all (for ``imuloco methods``). A module that a user adds
registers its class with :func:`register` when imported.
"""

from __future__ import annotations

import importlib

from imuloco.methods.base import REGISTRY, Method, load_model, register

# Built-in method name -> the module of imuloco.methods that registers it.
_BUILTIN: dict[str, str] = {
    "mean": "baselines", "ridge": "baselines", "knn": "baselines",
    "eom2014": "eom2014", "mousas2017": "mousas2017",
    "tautges2008": "tautges2008", "pca-local": "pca_local",
    "learned": "learned",
}
_OPTIONAL = {"torch": "deep"}  # missing module -> the extra that installs it


def method_names() -> list[str]:
    """Names of every built-in and registered method (installed or not)."""
    return sorted(set(_BUILTIN) | set(REGISTRY))


def method_class(name: str) -> type[Method]:
    """The class registered as ``name``, importing its module on first use.

    Raises KeyError for an unknown name or a method whose optional dependency is missing."""
    if name not in REGISTRY and name in _BUILTIN:
        try:
            importlib.import_module(f"imuloco.methods.{_BUILTIN[name]}")
        except ModuleNotFoundError as e:
            if e.name not in _OPTIONAL:
                raise
            raise KeyError(f"method {name!r} needs {e.name}: pip install "
                           f"'imuloco[{_OPTIONAL[e.name]}]'") from None
    if name not in REGISTRY:
        raise KeyError(f"unknown method {name!r}; available: {method_names()}")
    return REGISTRY[name]


def available_methods() -> dict[str, type[Method]]:
    """Every method whose dependencies are installed, by name (imports them all)."""
    out = {}
    for name in method_names():
        try:
            out[name] = method_class(name)
        except KeyError:
            continue
    return out


def get_method(name: str, **params) -> Method:
    """A new, unfitted method by name."""
    return method_class(name)(**params)


__all__ = ["REGISTRY", "Method", "available_methods", "get_method", "load_model",
           "method_class", "method_names", "register"]
