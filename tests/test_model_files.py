"""Model files: npz + JSON header, round trips, and clear failures on bad files."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from imuloco.errors import ModelFileError
from imuloco.methods import get_method, load_model
from imuloco.methods.modelfile import FORMAT_VERSION
from imuloco.methods.training import TEST_SEED_OFFSET, synthesize


@pytest.fixture(scope="module")
def signals(sample_db):
    return synthesize(sample_db.subset([5]), ["right_ankle"], "phone", TEST_SEED_OFFSET)[0].signals


@pytest.fixture(scope="module")
def models(sample_db):
    train = sample_db.subset([0, 1, 2, 3])
    return {n: get_method(n).fit(train, ["right_ankle"], "phone", 0)
            for n in ("mean", "ridge", "knn")}


@pytest.mark.parametrize("name", ["mean", "ridge", "knn"])
def test_round_trip_gives_identical_reconstructions(models, signals, tmp_path, name):
    method = models[name]
    path = method.save(tmp_path / f"{name}.npz")
    loaded = load_model(path)
    assert type(loaded) is type(method)
    assert loaded.get_params() == method.get_params()
    assert loaded.placements_ == method.placements_ and loaded.fps_ == method.fps_
    a, b = method.reconstruct_signals(signals), loaded.reconstruct_signals(signals)
    assert np.array_equal(a.rotations, b.rotations)
    assert np.array_equal(a.root, b.root)
    assert loaded.skeleton_.names == method.skeleton_.names
    assert np.array_equal(loaded.skeleton_.offsets, method.skeleton_.offsets)


def test_save_refuses_to_overwrite(models, tmp_path):
    path = models["mean"].save(tmp_path / "m.npz")
    with pytest.raises(FileExistsError):
        models["mean"].save(path)
    models["mean"].save(path, overwrite=True)


def _rewrite_header(src, dst, **changes):
    with np.load(src, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    header = json.loads(bytes(data["__header__"]).decode())
    header.update(changes)
    data["__header__"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(dst, **data)


def test_other_format_version_fails_clearly(models, tmp_path):
    path = models["ridge"].save(tmp_path / "r.npz")
    _rewrite_header(path, tmp_path / "old.npz", format_version=FORMAT_VERSION + 1)
    with pytest.raises(ModelFileError, match="version"):
        load_model(tmp_path / "old.npz")


def test_unknown_method_fails_clearly(models, tmp_path):
    path = models["ridge"].save(tmp_path / "r.npz")
    _rewrite_header(path, tmp_path / "x.npz", method="no-such-method")
    with pytest.raises(ModelFileError, match="unknown method"):
        load_model(tmp_path / "x.npz")


@pytest.mark.parametrize("keep", [0.5, 0.9])
def test_truncated_file_fails_clearly(models, tmp_path, keep):
    path = models["knn"].save(tmp_path / "k.npz")
    blob = path.read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(blob[: int(len(blob) * keep)])
    with pytest.raises(ModelFileError):
        load_model(cut)


def test_corrupted_file_fails_clearly(models, tmp_path):
    path = models["ridge"].save(tmp_path / "r.npz")
    blob = bytearray(path.read_bytes())
    mid = len(blob) // 2
    blob[mid: mid + 64] = bytes(64)  # zero a stretch inside the compressed arrays
    bad = tmp_path / "bad.npz"
    bad.write_bytes(bytes(blob))
    with pytest.raises(ModelFileError):
        load_model(bad)


def test_garbage_and_non_model_files_fail_clearly(tmp_path):
    (tmp_path / "text.npz").write_text("not a zip file at all")
    with pytest.raises(ModelFileError, match="not an imuloco model"):
        load_model(tmp_path / "text.npz")
    np.savez(tmp_path / "plain.npz", a=np.arange(3))  # a valid npz without our header
    with pytest.raises(ModelFileError, match="not an imuloco model"):
        load_model(tmp_path / "plain.npz")
    # an npz holding a pickled object array is refused, never unpickled
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z, z.open("__header__.npy", "w") as f:
        np.lib.format.write_array(f, np.array([{"x": 1}], dtype=object), allow_pickle=True)
    (tmp_path / "pickle.npz").write_bytes(buf.getvalue())
    with pytest.raises(ModelFileError):
        load_model(tmp_path / "pickle.npz")


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_model(tmp_path / "absent.npz")


def test_random_corruption_never_escapes_as_another_error(models, tmp_path):
    """Bytes overwritten anywhere: either the zip checks miss it (harmless padding) or loading
    raises ModelFileError; never a raw zlib/KeyError/TypeError."""
    blob = models["ridge"].save(tmp_path / "r.npz").read_bytes()
    rng = np.random.default_rng(0)
    bad = tmp_path / "c.npz"
    for _ in range(40):
        b = bytearray(blob)
        pos = int(rng.integers(0, len(b) - 8))
        b[pos: pos + 8] = rng.integers(0, 256, 8, dtype=np.uint8).tobytes()
        bad.write_bytes(bytes(b))
        try:
            load_model(bad)
        except ModelFileError:
            pass


def test_missing_arrays_fail_clearly(models, tmp_path):
    path = models["ridge"].save(tmp_path / "r.npz")
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files if k != "coef"}
    np.savez(tmp_path / "part.npz", **data)
    with pytest.raises(ModelFileError, match="incomplete"):
        load_model(tmp_path / "part.npz")


def test_training_protocol_travels_with_the_model(models, tmp_path):
    model = models["ridge"]
    assert model.protocol_["clips"] > 0 and model.protocol_["noise"] == model.noise_
    back = load_model(model.save(tmp_path / "m.npz"))
    assert back.protocol_ == model.protocol_
