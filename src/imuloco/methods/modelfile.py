"""The model file format: one ``.npz`` per fitted method, never a pickle.

A file holds the method's learned arrays plus ``__parents__`` and ``__offsets__`` (the output
skeleton) and ``__header__``, a JSON object: ``format_version``, ``method`` (registry name),
``params`` (hyperparameters), ``placements``, ``noise``, ``fps``, ``skeleton`` (names, body
map, end sites), ``protocol`` (what it was trained on) and ``values`` (the method's JSON-able
learned values). :func:`save_model` writes it, :func:`load_model` reads it back.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imuloco.core.skeleton import Skeleton
from imuloco.errors import ModelFileError, UnknownNameError
from imuloco.io.atomic import atomic_write, check_output

if TYPE_CHECKING:
    from imuloco.methods.base import Method

FORMAT_VERSION = 1


def save_model(method: Method, path: str | Path, overwrite: bool = False) -> Path:
    """Write the fitted ``method`` to one ``.npz`` file at ``path`` and return the path."""
    path = Path(path)
    check_output(path, overwrite)
    arrays, values = method.get_state()
    sk = method.skeleton_
    header = {
        "format_version": FORMAT_VERSION, "method": method.name, "params": method.get_params(),
        "placements": method.placements_, "noise": method.noise_, "fps": method.fps_,
        "skeleton": {"names": sk.names, "body_map": sk.body_map,
                     "end_sites": {str(k): v.tolist() for k, v in sk.end_sites.items()}},
        "protocol": getattr(method, "protocol_", {}), "values": values,
    }
    blob = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    with atomic_write(path) as f:
        np.savez_compressed(f, __header__=blob, __parents__=sk.parents,
                            __offsets__=sk.offsets, **arrays)
    return path


def load_model(path: str | Path) -> Method:
    """Load a model saved by :func:`save_model`. Never unpickles anything."""
    from imuloco.methods.registry import method_class

    path = Path(path)
    try:
        # open the file here: np.load leaks its own handle when the zip is truncated
        with open(path, "rb") as f, np.load(f, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
        header = json.loads(bytes(data.pop("__header__")).decode())
    except FileNotFoundError:
        raise
    except (zipfile.BadZipFile, zlib.error, ValueError, KeyError, OSError, EOFError) as e:
        raise ModelFileError(f"{path}: not an imuloco model file or corrupted ({e})") from None
    if not isinstance(header, dict):
        raise ModelFileError(f"{path}: not an imuloco model file (header is not a JSON object)")
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise ModelFileError(f"{path}: model file format version {version}, this imuloco reads "
                             f"version {FORMAT_VERSION}; retrain with `imuloco train`")
    name = header.get("method")
    try:
        cls = method_class(str(name))
    except UnknownNameError as e:
        raise ModelFileError(f"{path}: {e}") from None
    params = _current_params(path, cls, header.get("params"))
    try:  # a header or arrays that do not fit the method: missing keys, wrong shapes
        method = cls(**{**cls.legacy_params, **params})
        sk = header["skeleton"]
        method.set_setup(Skeleton(sk["names"], data.pop("__parents__"), data.pop("__offsets__"),
                                  {int(k): np.array(v) for k, v in sk["end_sites"].items()},
                                  sk["body_map"]),
                         header["fps"], header["placements"], header["noise"])
        method.protocol_ = header.get("protocol", {})
        method.set_state(data, header["values"])
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise ModelFileError(f"{path}: {name} model file is incomplete or corrupted "
                             f"({type(e).__name__}: {e})") from None
    return method


def _current_params(path: Path, cls: type[Method], params: object) -> dict[str, Any]:
    """``params`` of a file's header without the method's retired hyperparameters; a file
    trained with a retired option the code no longer has is refused."""
    if not isinstance(params, dict):
        raise ModelFileError(f"{path}: {cls.name} model file is incomplete or corrupted "
                             "(its header has no parameter table)")
    out = dict(params)
    for key, kept in cls.retired_params.items():
        if key in out and out.pop(key) != kept and kept is not None:
            raise ModelFileError(f"{path}: {cls.name} model trained with {key}={params[key]!r}, "
                                 f"an option this imuloco no longer has (only {kept!r}); "
                                 "retrain it with `imuloco train`")
    return out
