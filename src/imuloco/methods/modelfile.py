"""The model file format: one ``.npz`` per fitted method, never a pickle.

A file holds the method's learned arrays plus ``__parents__`` and ``__offsets__`` (the output
skeleton) and ``__header__``, a JSON object: ``format_version``, ``method`` (registry name),
``params`` (hyperparameters), ``placements``, ``noise``, ``fps``, ``skeleton`` (names, body
map, end sites), ``protocol`` (what it was trained on) and ``values`` (the method's JSON-able
learned values). :func:`save_model` writes it (atomically), :func:`load_model` reads it back
within limits (member sizes, declared array shapes, header size and depth, checked before
anything is decompressed; :func:`check_header` for the header's schema).
"""

from __future__ import annotations

import json
import math
import zipfile
import zlib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imuloco.core.skeleton import Skeleton
from imuloco.errors import ModelFileError, ParameterError, UnknownNameError
from imuloco.io.atomic import atomic_write, check_output
from imuloco.io.npz import declared
from imuloco.methods.registry import method_class
from imuloco.sensors.noise import NOISE_PRESETS
from imuloco.sensors.placement import PRESETS

if TYPE_CHECKING:
    from imuloco.methods.base import Method

FORMAT_VERSION = 1


# ``protocol_`` entries that say when and how long a model was trained, not what it computes
TIMING_KEYS = ("train_seconds", "trained_at")


def save_model(method: Method, path: str | Path, overwrite: bool = False,
               timing: bool = True) -> Path:
    """Write the fitted ``method`` to one ``.npz`` file at ``path`` and return the path.
    ``timing=False`` leaves :data:`TIMING_KEYS` out, so that a model fitted again to the same
    state is the same bytes (``batch`` resumes by the model file's hash)."""
    path = Path(path)
    check_output(path, overwrite)
    arrays, values = method.get_state()
    sk = method.skeleton_
    protocol = {k: v for k, v in getattr(method, "protocol_", {}).items()
                if timing or k not in TIMING_KEYS}
    header = {
        "format_version": FORMAT_VERSION, "method": method.name, "params": method.get_params(),
        "placements": method.placements_, "noise": method.noise_, "fps": method.fps_,
        "skeleton": {"names": sk.names, "body_map": sk.body_map,
                     "end_sites": {str(k): v.tolist() for k, v in sk.end_sites.items()}},
        "protocol": protocol, "values": values,
    }
    blob = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    with atomic_write(path) as f:
        np.savez_compressed(f, __header__=blob, __parents__=sk.parents,
                            __offsets__=sk.offsets, **arrays)
    return path


# limits of a model file, checked before anything is decompressed or allocated
MAX_ARRAY_BYTES = 1 << 30  # one array once unzipped; the shipped models' largest is ~1 MB
MAX_TOTAL_BYTES = 4 << 30  # all members together
MAX_MEMBERS = 10_000
MAX_HEADER_BYTES = 16 << 20
MAX_HEADER_DEPTH = 32  # JSON nesting of the header; save_model writes 5 levels
MIN_FPS, MAX_FPS = 1.0, 1000.0


class _Arrays(Mapping):
    """The arrays of a model file by name, each read when first asked for, after checking its
    declared dtype and shape against the size the zip declares (so a forged header cannot make
    numpy allocate terabytes): unused members are never decompressed."""

    def __init__(self, path: Path, zf: zipfile.ZipFile) -> None:
        self.path, self._zip = path, zf
        infos = zf.infolist()
        if len(infos) > MAX_MEMBERS:
            raise ModelFileError(f"{path}: {len(infos)} members, more than {MAX_MEMBERS}")
        self._infos = {i.filename.removesuffix(".npy"): i for i in infos}
        total = sum(i.file_size for i in infos)
        big = max(infos, key=lambda i: i.file_size, default=None)
        if big is not None and big.file_size > MAX_ARRAY_BYTES or total > MAX_TOTAL_BYTES:
            raise ModelFileError(f"{path}: member {big.filename!r} unzips to {big.file_size:,} "
                                 f"bytes ({total:,} in all); a model file's arrays are at most "
                                 f"{MAX_ARRAY_BYTES:,} bytes each, {MAX_TOTAL_BYTES:,} in all")
        self._cache: dict[str, np.ndarray] = {}

    def __iter__(self) -> Iterator[str]:
        return iter(self._infos)

    def __len__(self) -> int:
        return len(self._infos)

    def __getitem__(self, key: str) -> np.ndarray:
        if key not in self._cache:
            info = self._infos[key]  # KeyError: a missing array, reported by load_model
            with self._zip.open(info) as f:
                shape, dtype, nbytes = declared(f)
                if dtype.hasobject or nbytes > info.file_size:
                    raise ModelFileError(f"{self.path}: array {key!r} declares {dtype} of shape "
                                         f"{shape} ({nbytes:,} bytes) in {info.file_size:,} "
                                         "bytes")
            with self._zip.open(info) as f:
                arr = np.lib.format.read_array(f, allow_pickle=False)
            if arr.dtype.kind in "fc" and not np.isfinite(arr).all():
                raise ModelFileError(f"{self.path}: array {key!r} holds NaN or infinite values")
            self._cache[key] = arr
        return self._cache[key]


def load_model(path: str | Path) -> Method:
    """Load a model saved by :func:`save_model`. Never unpickles anything.

    Raises :class:`ModelFileError` naming ``path`` for anything but a readable model file of
    this format version whose header passes :func:`check_header` and whose arrays fit its
    method (``FileNotFoundError`` when there is no file).
    """
    path = Path(path)
    try:
        with open(path, "rb") as f, zipfile.ZipFile(f) as zf:
            arrays = _Arrays(path, zf)
            return _load(path, arrays)
    except FileNotFoundError:
        raise
    except ModelFileError:
        raise
    except (zipfile.BadZipFile, zlib.error, ValueError, KeyError, OSError, EOFError,
            MemoryError, RecursionError, NotImplementedError) as e:  # a corrupted zip or array
        # (NotImplementedError: zipfile on a version or compression it does not know)
        raise ModelFileError(f"{path}: not an imuloco model file or corrupted "
                             f"({type(e).__name__}: {e})") from None


def _load(path: Path, arrays: _Arrays) -> Method:
    header = _read_header(path, arrays)
    try:
        cls = method_class(header["method"])
    except UnknownNameError as e:
        raise ModelFileError(f"{path}: {e}") from None
    params = _current_params(path, cls, header["params"])
    try:  # the method's constraint table, before anything is built from the header
        method = cls(**{**cls.legacy_params, **params})
    except ParameterError as e:
        raise ModelFileError(f"{path}: header field 'params.{e.key}': {e}") from None
    try:  # a header or arrays that do not fit the method: missing keys, wrong shapes
        sk = header["skeleton"]
        method.set_setup(Skeleton(sk["names"], arrays["__parents__"], arrays["__offsets__"],
                                  {int(k): np.array(v) for k, v in sk["end_sites"].items()},
                                  sk["body_map"]),
                         header["fps"], header["placements"], header["noise"])
        method.protocol_ = header.get("protocol", {})
        method.set_state(_Without(arrays, ("__header__", "__parents__", "__offsets__")),
                         header["values"])
        _self_check(path, method)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, RuntimeError,
            np.linalg.LinAlgError) as e:
        # RuntimeError: torch refusing weights of another shape
        raise ModelFileError(f"{path}: {header['method']} model file is incomplete or corrupted "
                             f"({type(e).__name__}: {str(e)[:300]})") from None
    return method


def _self_check(path: Path, method: Method) -> None:
    """Reconstruct one second of a resting sensor: arrays of shapes that do not fit each other
    (which no header check sees) fail here, at loading, rather than in the user's run."""
    frames = max(2, round(method.fps_))
    signals = np.zeros((frames, 6 * len(method.placements_)))
    signals[:, 1::6] = 9.80665  # gravity along each sensor's y axis
    motion = method.reconstruct_signals(signals)
    if not (np.isfinite(motion.rotations).all() and np.isfinite(motion.root).all()):
        raise ModelFileError(f"{path}: {method.name} model reconstructs NaN or infinite values")


class _Without(Mapping):
    """``arrays`` without some keys (the file's own members), still read lazily."""

    def __init__(self, arrays: Mapping, hidden: tuple[str, ...]) -> None:
        self._arrays, self._hidden = arrays, hidden

    def __getitem__(self, key: str) -> np.ndarray:
        if key in self._hidden:
            raise KeyError(key)
        return self._arrays[key]

    def __iter__(self) -> Iterator[str]:
        return (k for k in self._arrays if k not in self._hidden)

    def __len__(self) -> int:
        return sum(1 for _ in self)


def _read_header(path: Path, arrays: _Arrays) -> dict[str, Any]:
    """The JSON header, size- and depth-limited, checked by :func:`check_header`."""
    if "__header__" not in arrays:
        raise ModelFileError(f"{path}: not an imuloco model file (no __header__ member)")
    blob = arrays["__header__"]
    if blob.dtype != np.uint8 or blob.ndim != 1 or blob.size > MAX_HEADER_BYTES:
        raise ModelFileError(f"{path}: the header must be at most {MAX_HEADER_BYTES:,} bytes of "
                             f"JSON, found {blob.dtype} of shape {blob.shape}")
    try:
        header = json.loads(blob.tobytes().decode("utf-8"))
    except RecursionError:
        raise ModelFileError(f"{path}: the header nests deeper than {MAX_HEADER_DEPTH} "
                             "levels") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ModelFileError(f"{path}: the header is not JSON ({e})") from None
    check_header(path, header)
    return header


def _depth(value: object) -> int:
    """Nesting depth of a JSON value (iterative: no recursion to exhaust)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, d = stack.pop()
        deepest = max(deepest, d)
        if d <= MAX_HEADER_DEPTH and isinstance(v, (dict, list)):
            stack += [(c, d + 1) for c in (v.values() if isinstance(v, dict) else v)]
    return deepest


def non_finite(value: object, where: str = "") -> str | None:
    """The path (``values.novelty_scale``, ``protocol.a[1].b``) of the first NaN or infinite
    number in a JSON value, None when there is none (iterative: no recursion to exhaust)."""
    stack = [(value, where)]
    while stack:
        v, at = stack.pop()
        if isinstance(v, float) and not math.isfinite(v):
            return at
        if isinstance(v, dict):
            stack += [(c, f"{at}.{k}" if at else str(k)) for k, c in reversed(v.items())]
        elif isinstance(v, list):
            stack += [(c, f"{at}[{i}]") for i, c in reversed(list(enumerate(v)))]
    return None


def check_header(path: str | Path, header: object) -> None:
    """The header's schema: raises :class:`ModelFileError` naming ``path`` and the field.

    ``format_version`` is :data:`FORMAT_VERSION`; ``method`` a name; ``params``, ``values``,
    ``protocol`` and ``skeleton`` objects (``skeleton`` with ``names`` a list of strings,
    ``body_map`` and ``end_sites`` objects); ``placements`` a non-empty list of distinct known
    placement names; ``noise`` a known noise preset; ``fps`` a number in
    :data:`MIN_FPS`..:data:`MAX_FPS`; nesting at most :data:`MAX_HEADER_DEPTH` levels; no
    NaN or infinite number anywhere. (``params`` pass the method's constraint table when
    :func:`load_model` constructs it.)
    """
    def bad(field: str, expected: str, value: object) -> ModelFileError:
        return ModelFileError(f"{path}: header field {field!r}: expected {expected}, found "
                              f"{json.dumps(value)[:80] if _depth(value) < 4 else '...'}")

    if not isinstance(header, dict):
        raise ModelFileError(f"{path}: not an imuloco model file (header is not a JSON object)")
    if _depth(header) > MAX_HEADER_DEPTH:
        raise ModelFileError(f"{path}: the header nests deeper than {MAX_HEADER_DEPTH} levels")
    at = non_finite(header)
    if at is not None:  # JSON's NaN and Infinity pass every range check (a novelty threshold
        # of NaN flagged no frame; a novelty scale of Infinity predicted 1.5 cm, not 47)
        raise ModelFileError(f"{path}: header field {at!r}: expected a finite number, found "
                             "NaN or Infinity")
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise ModelFileError(f"{path}: model file format version {version!r}, this imuloco "
                             f"reads version {FORMAT_VERSION}; retrain with `imuloco train`")
    if not isinstance(header.get("method"), str):
        raise bad("method", "a method name", header.get("method"))
    for key in ("params", "values", "skeleton"):
        if not isinstance(header.get(key), dict):
            raise bad(key, "an object", header.get(key))
    if not isinstance(header.get("protocol", {}), dict):
        raise bad("protocol", "an object", header["protocol"])
    places = header.get("placements")
    if not (isinstance(places, list) and places and all(p in PRESETS for p in places
                                                         if isinstance(p, str))
            and all(isinstance(p, str) for p in places) and len(set(places)) == len(places)):
        raise bad("placements", f"a non-empty list of distinct names from {sorted(PRESETS)}",
                  places)
    if not (isinstance(header.get("noise"), str) and header["noise"] in NOISE_PRESETS):
        raise bad("noise", f"one of {sorted(NOISE_PRESETS)}", header.get("noise"))
    fps = header.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or \
            not MIN_FPS <= fps <= MAX_FPS:
        raise bad("fps", f"a frame rate from {MIN_FPS:g} to {MAX_FPS:g}", fps)
    sk = header["skeleton"]
    names = sk.get("names")
    if not (isinstance(names, list) and names and all(isinstance(n, str) for n in names)):
        raise bad("skeleton.names", "a non-empty list of joint names", names)
    for key in ("body_map", "end_sites"):
        if not isinstance(sk.get(key), dict):
            raise bad(f"skeleton.{key}", "an object", sk.get(key))


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
