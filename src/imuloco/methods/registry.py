"""Methods by name: the registry behind ``bench``, ``train``, ``reconstruct`` and ``live``.

A method's name is stated once, as an entry point of the group ``imuloco.methods`` in
``pyproject.toml`` (``name = "module:Class"``, ``name = "module:Class [extra]"`` when it
needs an optional extra of the distribution); a third-party package adds its own methods the
same way, in its own ``pyproject.toml``, and needs no change here. The class learns its name
from there (:func:`imuloco.methods.names.registered_name`); a class may also be registered by
hand with :func:`register` (tests, notebooks), then it states its ``name`` itself.

:func:`method_class` imports a method's module on first use, so a command that needs
``ridge`` never imports torch; :func:`describe` tells what a method is without importing it.
"""

from __future__ import annotations

import ast
import importlib.util
import json
from collections.abc import Iterable
from dataclasses import dataclass
from importlib.metadata import EntryPoint, PackageNotFoundError, distribution
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from imuloco.errors import MissingExtraError, UnknownNameError
from imuloco.methods.names import GROUP, _entry_points

if TYPE_CHECKING:
    from imuloco.methods.base import Method

REGISTRY: dict[str, type[Method]] = {}  # by hand (register) and loaded entry points
M = TypeVar("M", bound="type[Method]")


def register(cls: M) -> M:
    """Class decorator: make a method available under ``cls.name`` (which it defines)."""
    if cls.name in REGISTRY and REGISTRY[cls.name] is not cls:
        raise ValueError(f"method name {cls.name!r} is registered twice")
    REGISTRY[cls.name] = cls
    return cls


def method_names() -> list[str]:
    """Names of every installed and registered method (their dependencies may be missing)."""
    return sorted(set(_entry_points()) | set(REGISTRY))


def _missing_requirement(ep: EntryPoint) -> str | None:
    """The first requirement of the entry point's extras that is not installed, if any."""
    if not ep.extras or ep.dist is None:
        return None
    for req in ep.dist.requires or []:
        spec, _, marker = req.partition(";")
        if not any(f'extra == "{x}"' in marker for x in ep.extras):
            continue
        name = spec.split("[")[0].strip()
        for sep in "=<>!~ ":
            name = name.split(sep)[0]
        try:
            distribution(name)
        except PackageNotFoundError:
            return name
    return None


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
            extra = ep.extras[0] if ep.extras else None
            if extra is None or e.name is None or e.name.split(".")[0] == "imuloco":
                raise
            raise MissingExtraError(f"method {name!r}", e.name, extra) from None
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
    """A new, unfitted method by name. Its hyperparameters must pass the class's constraint
    table (:mod:`imuloco.methods.params`, checked as the method is constructed):
    :class:`~imuloco.errors.ParameterError` (an InputError) naming the first that does not
    (``"True"`` reaching torch as a string failed deep inside a training)."""
    return method_class(name)(**params)


@dataclass(frozen=True)
class MethodInfo:
    """What ``imuloco methods`` prints about a method: its ``summary`` line, whether it
    ``supports_online``, and the extra to install (``missing``: the package it lacks)."""

    name: str
    summary: str
    supports_online: bool
    extra: str | None = None
    missing: str | None = None


def describe(name: str) -> MethodInfo:
    """A method's :class:`MethodInfo`, read from its class without importing its module when
    the class states ``summary`` and ``supports_online`` as literals (importing a method costs
    seconds: scipy, scikit-learn, torch); otherwise from the imported class."""
    ep = _entry_points().get(name)
    if ep is None:  # registered by hand
        cls = method_class(name)
        return MethodInfo(name, cls.summary, cls.supports_online)
    extra = ep.extras[0] if ep.extras else None
    missing = _missing_requirement(ep)
    found = _class_literals(ep.module, ep.attr, ("summary", "supports_online"))
    if "summary" not in found and missing is None:
        cls = method_class(name)
        found = {"summary": cls.summary, "supports_online": cls.supports_online}
    return MethodInfo(name, str(found.get("summary", "")),
                      bool(found.get("supports_online", False)), extra, missing)


def _class_literals(module: str, cls: str, keys: tuple[str, ...]) -> dict[str, Any]:
    """Literal class attributes ``keys`` of class ``cls`` in ``module``'s source, following
    base classes defined in the same module; nothing is imported or executed (the language's
    own parser, :mod:`ast`, reads the file). Empty when the source cannot be found."""
    source = _module_source(module)
    if source is None:
        return {}
    classes = {n.name: n for n in ast.parse(source).body if isinstance(n, ast.ClassDef)}
    out: dict[str, Any] = {}
    todo = [cls]
    while todo and len(out) < len(keys):
        node = classes.get(todo.pop(0))
        if node is None:
            continue
        for stmt in node.body:
            target, value = None, None
            if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1:
                target, value = stmt.targets[0], stmt.value
            elif isinstance(stmt, ast.AnnAssign):
                target, value = stmt.target, stmt.value
            if isinstance(target, ast.Name) and target.id in keys and value is not None:
                try:
                    out.setdefault(target.id, ast.literal_eval(value))
                except ValueError:
                    continue
        todo += [b.id for b in node.bases if isinstance(b, ast.Name)]
    return out


def _module_source(module: str) -> str | None:
    """The source text of a module of a regular package, found without importing it (finding
    a dotted name with importlib would import its parent packages)."""
    top, *rest = module.split(".")
    spec = importlib.util.find_spec(top)
    if spec is None:
        return None
    if not rest:
        return Path(spec.origin).read_text() if spec.origin else None
    for root in spec.submodule_search_locations or []:
        for path in (Path(root, *rest[:-1], rest[-1] + ".py"), Path(root, *rest, "__init__.py")):
            if path.is_file():
                return path.read_text(encoding="utf-8")
    return None


PYTHON_LITERALS = {"True": "true", "False": "false", "None": "null"}


def parse_params(items: Iterable[str], where: str = "parameter") -> dict[str, Any]:
    """``key=value`` strings -> a dict of hyperparameters; values parsed as JSON when they can
    be (numbers, ``true``, ``null``, lists; also Python's ``True``, ``False``, ``None``),
    else kept as stripped strings.

    Raises :class:`UnknownNameError` naming ``where`` for an item without ``=``."""
    params: dict[str, Any] = {}
    for item in items:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise UnknownNameError(f"{where}: expected key=value, got {item!r}")
        value = PYTHON_LITERALS.get(value.strip(), value)
        try:
            params[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            params[key.strip()] = value.strip()
    return params


def parse_method_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"eom2014[variant=mlp-no-hmm;context=7]"`` -> ``("eom2014", {"variant": "mlp-no-hmm",
    "context": 7})``: a method name with hyperparameters (:func:`parse_params`). Lets one
    bench compare variants of a method (e.g. the 2014 paper's ablation)."""
    name, bracket, rest = spec.partition("[")
    if bracket and not rest.endswith("]"):  # "mean[" ran as a method named "mean["
        raise UnknownNameError(f"method {spec!r}: expected NAME[key=value;key=value]")
    return name.strip(), parse_params(filter(None, rest[:-1].split(";")), f"method {spec!r}")
