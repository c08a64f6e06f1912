"""Reconstruction methods behind one interface (:class:`imuloco.methods.base.Method`).

:mod:`~imuloco.methods.base` is the interface, :mod:`~imuloco.methods.registry` finds methods
by name (entry points of the group ``imuloco.methods``), :mod:`~imuloco.methods.modelfile`
saves and loads fitted methods. Each method is a module (``baselines``, ``pca_local``) or a
sub-package with one step per module (``eom2014``, ``mousas2017``, ``tautges2008``,
``learned``).
"""

from __future__ import annotations

from imuloco.methods.base import Method
from imuloco.methods.modelfile import load_model
from imuloco.methods.registry import (
    REGISTRY,
    available_methods,
    get_method,
    method_class,
    method_names,
    register,
)

__all__ = ["REGISTRY", "Method", "available_methods", "get_method", "load_model",
           "method_class", "method_names", "register"]
