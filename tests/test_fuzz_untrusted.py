"""The fuzzer's classes of issue 42 (items 11, 12, 15-18): phone exports (units per column, zip
folders, links) and the live server (messages, requests, floods), judged as the issue asks, and
their oracles shown to catch the bugs they were written for."""

from __future__ import annotations

import logging
import random

import pytest

from imuloco.lab.fuzz import judge, run_fuzz, seed_files


@pytest.fixture(autouse=True)
def _logging_back():
    yield
    logging.disable(logging.NOTSET)  # judge() silences logging as the fuzz workers do


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    return seed_files(tmp_path_factory.mktemp("seeds"))


def _case(tmp_path, reader, seeds, attack_kind, seed=0):
    """The files of the first structured attack of ``reader`` whose mutation names
    ``attack_kind``, written under ``tmp_path``."""
    from imuloco.lab.fuzz import ATTACKS

    rng = random.Random(seed)
    for _ in range(500):
        mutation, files = ATTACKS[reader](dict(rng.choice(seeds[reader])), rng)
        if attack_kind in mutation:
            break
    else:
        raise AssertionError(f"no {attack_kind} attack")
    paths = []
    tmp_path.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(data)
        paths.append(tmp_path / name)
    return paths


def test_fuzzed_exports_end_in_clean_errors():
    r = run_fuzz(150, ("exports",), timeout=30.0)["exports"]
    assert r["wrong exception type"] == r["hang"] == r["garbage accepted"] == 0, r["examples"]
    assert r["clean"] > 40 and r["accepted"] > 10  # both outcomes are exercised


def test_fuzzed_live_messages_end_in_clean_closes():
    # 30 s an input: a verdict on the server, not on the speed of a loaded machine
    r = run_fuzz(40, ("live",), timeout=30.0)["live"]
    assert r["wrong exception type"] == r["hang"] == r["garbage accepted"] == 0, r["examples"]
    assert r["clean"] > 20 and r["accepted"] >= 2  # about 87 % / 13 % over 1,000 inputs


@pytest.mark.parametrize("attack, undo, verdict", [
    ("folders-", ("imuloco.io.sensorlog._one_folder", lambda path, infos: None), "folders"),
    ("link-out-valid", ("imuloco.io.sensorlog._inside", lambda path, folder: True), "link"),
])
def test_export_oracles_catch_what_they_were_written_for(tmp_path, seeds, monkeypatch, attack,
                                                         undo, verdict):
    """With a fix undone the same input is garbage accepted."""
    for seed in range(100):  # an attack the fix refuses (tables in two folders, a link out)
        paths = _case(tmp_path / str(seed), "exports", seeds, attack, seed)
        outcome, detail = judge("exports", paths)
        if outcome == "clean" and verdict in detail:
            break
    else:
        raise AssertionError(f"no {attack} input refused for its {verdict}")
    monkeypatch.setattr(*undo)
    outcome, detail = judge("exports", paths)
    assert outcome == "garbage accepted" and verdict in detail, detail


def test_live_oracle_catches_implausible_samples_taken(tmp_path, seeds, monkeypatch):
    import json

    import numpy as np

    rows = np.array(json.loads(seeds["live"][1]["c0-m000.msg"])["rows"])
    bad = rows.copy()
    bad[:, 0] += rows[-1, 0] - rows[0, 0] + 0.01
    bad[:, 1:] = 1e200
    paths = [tmp_path / "c0-m000.msg", tmp_path / "c0-m001.msg"]
    paths[0].write_text(json.dumps({"rows": rows.tolist()}))
    paths[1].write_text(json.dumps({"rows": bad.tolist()}))
    outcome, detail = judge("live", paths)
    assert outcome == "clean" and "samples dropped" in detail, detail
    monkeypatch.setattr("imuloco.app.live.server.plausible", lambda rows, sensors: (rows, None))
    outcome, detail = judge("live", paths)
    assert outcome == "garbage accepted" and "without a word" in detail, detail
