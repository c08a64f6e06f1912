"""Reconstruction methods behind one interface (:class:`imuloco.methods.base.Method`).

Importing this package registers the built-in methods; :func:`get_method` builds one by name.
"""

from __future__ import annotations

import importlib

from imuloco.methods.base import REGISTRY, Method, load_model, register

# Modules that register methods. A module whose optional dependency (torch) is missing is
# skipped, and its method is absent from the registry.
_BUILTIN = ("baselines",)
for _mod in _BUILTIN:
    try:
        importlib.import_module(f"imuloco.methods.{_mod}")
    except ImportError as _e:  # pragma: no cover - depends on the installed extras
        if "torch" not in str(_e):
            raise


def get_method(name: str, **params) -> Method:
    """A new, unfitted method by registry name."""
    if name not in REGISTRY:
        raise KeyError(f"unknown method {name!r}; available: {sorted(REGISTRY)}")
    return REGISTRY[name](**params)


__all__ = ["REGISTRY", "Method", "get_method", "load_model", "register"]
