"""Reconstruction methods behind one interface (:class:`imuloco.methods.base.Method`).

:mod:`~imuloco.methods.base` is the interface, :mod:`~imuloco.methods.training` its training
input (:class:`~imuloco.methods.training.TrainingSet`), :mod:`~imuloco.methods.registry` finds
methods by name (entry points of the group ``imuloco.methods``),
:mod:`~imuloco.methods.modelfile` saves and loads fitted methods. Each method is a module
(``baselines``, ``pca_local``) or a sub-package with one step per module (``eom2014``,
``mousas2017``, ``tautges2008``, ``learned``).
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

from imuloco.methods.registry import (
    REGISTRY,
    available_methods,
    describe,
    get_method,
    method_class,
    method_names,
    register,
)

if TYPE_CHECKING:
    from imuloco.methods.base import Method
    from imuloco.methods.modelfile import load_model

__all__ = ["REGISTRY", "Method", "available_methods", "describe", "get_method", "load_model",
           "method_class", "method_names", "register"]

# imported on first use (PEP 562): the registry alone does not import numpy, so listing the
# methods (``imuloco methods``) stays fast
_LAZY = {"Method": "imuloco.methods.base", "load_model": "imuloco.methods.modelfile"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'imuloco.methods' has no attribute {name!r}")
