"""Model files: npz + JSON header, round trips, and clear failures on bad files."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

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


# --- limits and the header's schema (issue 18): every bad file is a ModelFileError with its path

@pytest.mark.parametrize("changes, field", [
    ({"fps": -1}, "fps"), ({"fps": 0}, "fps"), ({"fps": 1e308}, "fps"), ({"fps": True}, "fps"),
    ({"fps": "30"}, "fps"), ({"placements": []}, "placements"),
    ({"placements": "nose"}, "placements"), ({"placements": ["nose"]}, "placements"),
    ({"placements": ["right_ankle", "right_ankle"]}, "placements"),
    ({"params": [1, 2]}, "params"), ({"noise": "loud"}, "noise"), ({"values": None}, "values"),
    ({"skeleton": {"names": []}}, "skeleton.names"), ({"method": 3}, "method")])
def test_header_schema(models, tmp_path, changes, field):
    path = models["ridge"].save(tmp_path / "r.npz")
    bad = tmp_path / "bad.npz"
    _rewrite_header(path, bad, **changes)
    with pytest.raises(ModelFileError, match=f"{bad}: header field '{field}'"):
        load_model(bad)


def test_deeply_nested_header(models, tmp_path):
    path = models["ridge"].save(tmp_path / "r.npz")
    with np.load(path, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    text = bytes(data["__header__"]).decode()
    for depth in (40, 100_000):  # past the limit, and past Python's recursion limit
        deep = text.replace('"protocol": {', '"protocol": {"x": ' + "[" * depth + "]" * depth + ",")
        data["__header__"] = np.frombuffer(deep.encode(), dtype=np.uint8)
        np.savez(tmp_path / "deep.npz", **data)
        with pytest.raises(ModelFileError, match="nests deeper"):
            load_model(tmp_path / "deep.npz")


def _add_member(src, dst, name, header_bytes):
    """Copy a model file and add a member whose raw .npy bytes are given."""
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as b:
        for info in a.infolist():
            b.writestr(info, a.read(info))
        b.writestr(name, header_bytes)


def test_unused_huge_member_is_refused_before_decompressing(models, tmp_path, monkeypatch):
    """A member that unzips to more than the limit (here lowered to 1 MiB; 32 MiB of zeros
    compress to 32 KB) is refused from its declared size: never opened."""
    from imuloco.methods import modelfile

    monkeypatch.setattr(modelfile, "MAX_ARRAY_BYTES", 1 << 20)
    path = models["ridge"].save(tmp_path / "r.npz")
    big = tmp_path / "big.npz"
    with zipfile.ZipFile(path) as a, zipfile.ZipFile(big, "w", zipfile.ZIP_DEFLATED) as b:
        for info in a.infolist():
            b.writestr(info, a.read(info))
        b.writestr("junk.npy", bytes(32 << 20))
    assert big.stat().st_size < 200_000
    opened = []
    real_open = zipfile.ZipFile.open
    monkeypatch.setattr(zipfile.ZipFile, "open",
                        lambda self, name, *a, **k: opened.append(str(getattr(name, "filename",
                                                                                name)))
                        or real_open(self, name, *a, **k))
    with pytest.raises(ModelFileError, match="'junk.npy' unzips to 33,554,432 bytes"):
        load_model(big)
    assert opened == []


def test_unused_small_member_is_never_read(models, tmp_path):
    path = models["ridge"].save(tmp_path / "r.npz")
    _add_member(path, tmp_path / "extra.npz", "unused.npy", b"not even an npy array")
    assert load_model(tmp_path / "extra.npz").fps_ == models["ridge"].fps_


def test_forged_array_shape_is_refused(models, tmp_path):
    """A .npy header declaring 10^12 floats in a few bytes: no MemoryError, no allocation."""
    path = models["ridge"].save(tmp_path / "r.npz")
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False,
                                               "shape": (10**6, 10**6)})
    forged = tmp_path / "forged.npz"
    with zipfile.ZipFile(path) as a, zipfile.ZipFile(forged, "w") as b:
        for info in a.infolist():
            b.writestr(info, buf.getvalue() + b"\0" * 64 if info.filename == "coef.npy"
                       else a.read(info))
    with pytest.raises(ModelFileError, match=f"{forged}: array 'coef' declares"):
        load_model(forged)


def test_csv_given_as_model_gives_no_pickle_advice(tmp_path):
    (tmp_path / "some.csv").write_text("time_s,acc_x\n0,1\n")
    with pytest.raises(ModelFileError) as e:
        load_model(tmp_path / "some.csv")
    assert str(tmp_path / "some.csv") in str(e.value) and "pickle" not in str(e.value)


@pytest.mark.skipif(not __import__("importlib").util.find_spec("torch"), reason="needs torch")
def test_reshaped_weight_is_a_model_file_error(tmp_path):
    from imuloco.data import MODELS_DIR

    src = MODELS_DIR / "learned_right_ankle.npz"
    dst = tmp_path / "reshaped.npz"
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w") as b:
        for info in a.infolist():
            data = a.read(info)
            if info.filename.endswith("inp.0.bias.npy"):  # of every member of an ensemble
                arr = np.lib.format.read_array(io.BytesIO(data))
                out = io.BytesIO()
                np.lib.format.write_array(out, arr[: len(arr) // 2])
                data = out.getvalue()
            b.writestr(info, data)
    with pytest.raises(ModelFileError, match=f"{dst}: learned model file is incomplete"):
        load_model(dst)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(["fps", "placements", "noise", "params", "values", "skeleton",
                            "protocol", "method", "format_version"]),
       value=st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(),
                          lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(), c,
                                                                            max_size=3),
                          max_leaves=8))
def test_any_header_value_loads_or_fails_cleanly(models, tmp_path, key, value):
    path = tmp_path / "r.npz"
    if not path.exists():
        models["ridge"].save(path)
    _rewrite_header(path, tmp_path / "h.npz", **{key: value})
    try:
        m = load_model(tmp_path / "h.npz")
    except ModelFileError as e:
        assert str(tmp_path / "h.npz") in str(e)
        return
    assert 1 <= m.fps_ <= 1000 and m.placements_


def test_zip_of_an_unknown_version_is_a_model_file_error(models, tmp_path):
    """zipfile raises NotImplementedError for a version it does not know (a flipped byte)."""
    blob = bytearray(models["ridge"].save(tmp_path / "r.npz").read_bytes())
    at = blob.find(b"PK\x01\x02")
    blob[at + 6] = 166  # "version needed to extract" of the first member: 16.6
    (tmp_path / "v.npz").write_bytes(bytes(blob))
    with pytest.raises(ModelFileError, match="v.npz"):
        load_model(tmp_path / "v.npz")


# --- the method's parameter table checked at load; no non-finite number in a header (issue 42:
# 9, 13): every field named, refused before anything is built from it

def _edit_header(src, dst, edit):
    """Copy model file ``src`` to ``dst`` with ``edit(header)`` applied to its JSON header
    (written with NaN and Infinity as Python's json writes them)."""
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w") as b:
        for info in a.infolist():
            data = a.read(info)
            if info.filename == "__header__.npy":
                header = json.loads(bytes(np.lib.format.read_array(io.BytesIO(data))).decode())
                edit(header)
                out = io.BytesIO()
                np.lib.format.write_array(
                    out, np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
                data = out.getvalue()
            b.writestr(info, data)
    return dst


@pytest.mark.parametrize("key, value, words", [
    ("window", 100000, "expects value in [1, 1000]"), ("window", 0, "expects value in"),
    ("window", 2.5, "whole number"), ("alpha", -1.0, "expects value in [0, inf)"),
    ("alpha", "big", "finite number"), ("nosuch", 1, "no parameter")])
def test_parameters_out_of_the_methods_table_are_refused_at_load(models, tmp_path, key, value,
                                                                 words):
    path = models["ridge"].save(tmp_path / "r.npz")
    bad = _edit_header(path, tmp_path / "bad.npz", lambda h: h["params"].update({key: value}))
    with pytest.raises(ModelFileError, match=f"{bad}: header field 'params.{key}'") as caught:
        load_model(bad)
    assert words in str(caught.value)


@pytest.mark.parametrize("key, value", [
    ("members", 100000), ("layers", 5000), ("lag", 1e7), ("hidden", 10**9), ("lag", -1),
    ("bidirectional", "yes")])
def test_a_learned_header_beyond_its_ranges_is_refused_before_building_it(tmp_path, key,
                                                                          value):
    """``members: 100000``, ``layers: 5000`` or ``lag: 1e7`` ran for 20 s and took 2.5 GB."""
    pytest.importorskip("torch")
    from imuloco.data import MODELS_DIR

    bad = _edit_header(MODELS_DIR / "learned_right_ankle.npz", tmp_path / "big.npz",
                       lambda h: h["params"].update({key: value}))
    with pytest.raises(ModelFileError, match=f"{bad}: header field 'params.{key}'"):
        load_model(bad)


@pytest.mark.parametrize("where, key, value", [
    ("values", "novelty_threshold", float("nan")), ("values", "novelty_scale", float("inf")),
    ("values", "flat_pitch", float("-inf")), ("protocol", "seed", float("nan")),
    ("params", "lr", float("nan"))])
def test_non_finite_numbers_in_a_header_are_refused_by_key(tmp_path, where, key, value):
    """NaN flagged no frame at all; Infinity predicted 1.5 cm where the model says 47."""
    pytest.importorskip("torch")
    from imuloco.data import MODELS_DIR

    bad = _edit_header(MODELS_DIR / "learned_right_ankle.npz", tmp_path / "nan.npz",
                       lambda h: h[where].update({key: value}))
    with pytest.raises(ModelFileError, match=f"{bad}: header field '{where}.{key}'"):
        load_model(bad)


def test_non_finite_numbers_deep_in_a_header_are_refused(models, tmp_path):
    path = models["ridge"].save(tmp_path / "r.npz")
    bad = _edit_header(path, tmp_path / "deep.npz",
                       lambda h: h["protocol"].update({"a": [1, {"b": float("inf")}]}))
    with pytest.raises(ModelFileError, match=r"header field 'protocol.a\[1\].b'"):
        load_model(bad)
