"""Method names as the ``imuloco.methods`` entry points state them (``pyproject.toml``).

The bottom of the methods' layers: :mod:`imuloco.methods.base` names a class by it
(:func:`registered_name`) and :mod:`imuloco.methods.registry` finds a class by name, neither
importing the other.
"""

from __future__ import annotations

from functools import cache
from importlib.metadata import EntryPoint, entry_points

GROUP = "imuloco.methods"


@cache
def _entry_points() -> dict[str, EntryPoint]:
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def registered_name(cls: type) -> str:
    """The entry-point name of ``cls`` or of the nearest registered class it derives from."""
    targets = {(ep.module, ep.attr): name for name, ep in _entry_points().items()}
    for c in cls.__mro__:
        name = targets.get((c.__module__, c.__qualname__))
        if name is not None:
            return name
    raise AttributeError(f"method class {cls.__module__}.{cls.__qualname__} has no name: "
                         f"give it an entry point in the group {GROUP!r} or a class attribute "
                         "`name`")
