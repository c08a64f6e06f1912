"""Writing a reconstruction for animation tools: on a rig preset (``--rig``), as BVH or glTF
chosen by the output's suffix; any other suffix is refused before any work.

``reconstruct``, ``batch`` and ``demo`` write through :func:`write_reconstruction`. The T-pose
rest of a skeleton of the bundled sample's rig family (that of every model trained on it, the
shipped ones included) is measured once on the sample's poses (:func:`rest_of`), so that every
file written on it has the same rest pose, whether from one piece or many.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from imuloco.core.motion import Motion
from imuloco.core.retarget import Rig, same_family
from imuloco.core.rigs import (
    DEFAULT_RIG,
    MODEL,
    apply_rig,
    check_rig_name,
    measure_rest,
    tpose_rest,
)
from imuloco.core.skeleton import Skeleton
from imuloco.errors import InputError, UnknownNameError
from imuloco.io.bvh import write_bvh
from imuloco.io.database import load_sample
from imuloco.io.gltf import pygltflib_module, write_gltf
from imuloco.measures.gait import stature

MOTION_SUFFIXES = (".bvh", ".glb", ".gltf")


def check_motion_output(path: str | Path, what: str = "output") -> Path:
    """``path`` when its suffix names a motion format written here (:data:`MOTION_SUFFIXES`)
    whose writer is installed; else :class:`InputError` listing them (nothing is written as
    something else) or :class:`imuloco.errors.MissingExtraError`."""
    path = Path(path)
    if path.suffix.lower() not in MOTION_SUFFIXES:
        raise InputError(f"{path}: cannot write a {path.suffix or 'suffix-less'} file as the "
                         f"{what}; expected {', '.join(MOTION_SUFFIXES)} (BVH, glTF binary, "
                         "glTF JSON)")
    if path.suffix.lower() != ".bvh":
        pygltflib_module()
    return path


def check_report_output(path: str | Path) -> Path:
    """``path`` when it is a ``.json`` report; else :class:`InputError` (the report is JSON;
    a markdown ``.md`` beside it is not written yet)."""
    path = Path(path)
    if path.suffix.lower() != ".json":
        raise InputError(f"{path}: the report is written as JSON: give a .json file "
                         "(other suffixes are refused, not written as JSON)")
    return path


@functools.lru_cache(maxsize=1)
def _sample_rest() -> tuple[Rig, np.ndarray]:
    """The bundled sample's rig (:meth:`Rig.measure` on all its clips, 1.2 s) and T-pose rest."""
    rig = Rig.measure(load_sample().clips, where="the bundled sample")
    return rig, tpose_rest(rig)


def sample_rest(skeleton: Skeleton) -> np.ndarray | None:
    """The bundled sample's T-pose rest (J, 4) when ``skeleton`` is of its rig family
    (:func:`imuloco.core.retarget.same_family`), else None: a rest known before any pose
    (the live mode's)."""
    rig, rest = _sample_rest()
    return rest if same_family(skeleton, rig.skeleton) else None


def rest_of(motion: Motion) -> np.ndarray:
    """The T-pose rest (J, 4) of ``motion``'s skeleton (:func:`imuloco.core.rigs.tpose_rest`):
    the bundled sample's when the skeleton is of its rig family (:func:`sample_rest`), else
    measured on ``motion`` itself."""
    rest = sample_rest(motion.skeleton)
    return measure_rest(motion) if rest is None else rest


def figure_height(skeleton: Skeleton) -> float | None:
    """The body height (metres) a figure on ``skeleton`` stands for: gait's stature, from the
    legs (:func:`imuloco.measures.gait.stature`; the ``--height`` a reconstruction was scaled
    to), which the writers' head End Site reaches at rest (:func:`imuloco.io.bvh.end_sites`);
    None for a rig without legs."""
    try:
        return stature(skeleton)
    except UnknownNameError:  # a rig without legs: the head keeps its End Site
        return None


def write_reconstruction(motion: Motion, path: str | Path, rig: str | None = DEFAULT_RIG,
                         unit: str = "cm", overwrite: bool = False,
                         rest: np.ndarray | None = None) -> Path:
    """Write ``motion`` to ``path`` (``.bvh``: lengths in ``unit``; ``.glb``/``.gltf``: metres)
    on preset ``rig`` (:func:`imuloco.core.rigs.apply_rig`; None or ``model``: as it is, e.g.
    a motion already retargeted onto the user's ``--skeleton``), the figure at rest as tall as
    :func:`figure_height`. ``rest``: the T-pose rest of ``motion``'s skeleton (:func:`rest_of`
    when None). Returns the path."""
    path = check_motion_output(path)
    out = motion
    if rig is not None and check_rig_name(rig) != MODEL:
        out = apply_rig(motion, rig, rest_of(motion) if rest is None else rest)
    height = figure_height(out.skeleton)
    if path.suffix.lower() == ".bvh":
        return write_bvh(out, path, unit=unit, overwrite=overwrite, height=height)
    return write_gltf(out, path, overwrite=overwrite, height=height)
