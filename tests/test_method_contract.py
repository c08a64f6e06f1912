"""The method contract every registered method keeps (imuloco.methods.base): one explicit
training input, a clear error before fitting, scikit-learn's hyperparameter conventions, and
whether the method pins its own feet."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sklearn.base import clone

from imuloco.errors import NotFittedError, UnknownNameError
from imuloco.methods import get_method, method_class, method_names
from imuloco.methods.baselines import MeanPose
from imuloco.methods.training import TrainingSet, model_frames
from imuloco.sensors.simulate import simulate

NAMES = method_names()


@pytest.fixture(scope="module")
def recording(sample_db):
    return simulate(sample_db.clips[0].slice(0, 60), ["right_ankle"], 100.0, "phone", seed=3)


@pytest.fixture(scope="module")
def small_set(sample_db):
    return TrainingSet.synthesize(sample_db.subset(range(3)), ["right_ankle"], "phone", seed=1)


@pytest.mark.parametrize("name", NAMES)
def test_using_a_method_before_fitting_raises_not_fitted(name, recording):
    method = get_method(name)
    with pytest.raises(NotFittedError, match=rf"method '{name}' is not fitted yet .*call fit"):
        method.reconstruct(recording)
    with pytest.raises(NotFittedError, match="not fitted"):
        method.reconstruct_signals(np.zeros((20, 6)))
    with pytest.raises(NotFittedError, match="not fitted"):
        method.save("never-written.npz")
    if method.supports_online:
        with pytest.raises(NotFittedError, match="not fitted"):
            method.stream()
    # code written against AttributeError (getattr with a default, hasattr) keeps working
    assert getattr(method, "protocol_", None) is None and not hasattr(method, "fps_")


@pytest.mark.parametrize("name", NAMES)
def test_get_params_set_params_round_trip(name):
    cls = method_class(name)
    method = cls()
    params = method.get_params()
    assert cls(**params).get_params() == params
    assert method.set_params(**params) is method and method.get_params() == params
    assert clone(method).get_params() == params  # scikit-learn's clone works on methods
    assert repr(method) == f"{cls.__name__}()"  # defaults are not printed
    with pytest.raises(UnknownNameError, match="no hyperparameter 'no_such_thing'"):
        method.set_params(no_such_thing=1)


def test_set_params_changes_what_is_learned_and_repr_shows_it(small_set):
    ridge = get_method("ridge").set_params(alpha=1e3, window=5)
    assert repr(ridge) == "RidgePose(window=5, alpha=1000.0)"
    ridge.fit_set(small_set)
    assert ridge.coef_.shape[1] == 5 * 6
    stiff = np.abs(ridge.coef_).sum()
    loose = np.abs(get_method("ridge", alpha=1e-3, window=5).fit_set(small_set).coef_).sum()
    assert stiff < loose


def test_fit_set_learns_from_its_input_alone_and_records_the_setup(small_set, sample_db):
    method = get_method("ridge")
    assert method.fit_set(small_set) is method
    assert method.placements_ == ["right_ankle"] and method.noise_ == "phone"
    assert method.fps_ == float(sample_db.clips[0].fps)
    assert method.skeleton_ is small_set.skeleton
    assert method.protocol_["clips"] == 3 and method.protocol_["seed"] == 1
    assert method.protocol_["frames"] == sum(c.num_frames for c in sample_db.clips[:3])
    # fit = synthesize + fit_set: the same learned state
    again = get_method("ridge").fit(sample_db.subset(range(3)), ["right_ankle"], "phone", 1)
    np.testing.assert_array_equal(again.coef_, method.coef_)


def test_training_set_is_frozen_and_checked(small_set):
    with pytest.raises(dataclasses.FrozenInstanceError):
        small_set.noise = "clean"
    assert isinstance(small_set.examples, tuple) and small_set.placements == ("right_ankle",)
    with pytest.raises(ValueError, match="empty"):
        TrainingSet.from_examples([], ["right_ankle"], "phone")
    with pytest.raises(ValueError, match=r"not \(T, 12\)"):
        TrainingSet.from_examples(small_set.examples, ["right_ankle", "pelvis"], "phone")


def test_model_frames_is_one_grid_at_the_model_rate(recording):
    rows = model_frames(recording, 30.0)
    span = recording.times[-1] - recording.times[0]
    assert rows.shape == (round(span * 30.0) + 1, 6)
    assert np.all(np.isfinite(rows))


@pytest.mark.parametrize(("name", "params", "pins"), [
    ("eom2014", {}, True), ("eom2014", {"foot_cleanup": False}, False),
    ("mousas2017", {}, True), ("mousas2017", {"foot_cleanup": False}, False),
    ("learned", {}, True), ("ridge", {}, False), ("mean", {}, False),
])
def test_a_method_says_whether_it_pins_its_feet(name, params, pins):
    assert get_method(name, **params).pins_feet is pins


class _SelfPinningMean(MeanPose):
    """The mean pose, claiming to pin its own feet (the pipeline must then leave it be)."""

    name = "self-pinning-mean"

    @property
    def pins_feet(self) -> bool:
        return True


def test_the_pipeline_pins_only_methods_that_do_not_pin_themselves(small_set, recording):
    from imuloco.app.pipeline import reconstruct_recording

    own = _SelfPinningMean().fit_set(small_set)
    motion, info = reconstruct_recording(recording, own, calibrate=False)
    assert info["feet_pinned_by"] == "method"
    np.testing.assert_array_equal(motion.root, own.reconstruct(recording).root)
    plain = MeanPose().fit_set(small_set)
    motion, info = reconstruct_recording(recording, plain, calibrate=False)
    assert info["feet_pinned_by"] == "pipeline"
    _, info = reconstruct_recording(recording, plain, calibrate=False, pin=False)
    assert info["feet_pinned_by"] == "none"


def test_each_method_takes_its_name_from_its_entry_point():
    from importlib.metadata import entry_points

    from imuloco.methods.base import Method

    for ep in entry_points(group="imuloco.methods"):
        cls = method_class(ep.name)
        assert cls.name == ep.name and cls().name == ep.name
    assert _SelfPinningMean.name == "self-pinning-mean"  # stated by hand, wins

    class Tweaked(MeanPose):  # a subclass answers to its registered parent's name
        pass

    assert Tweaked.name == "mean"

    class Stray(Method):
        pass

    with pytest.raises(AttributeError, match="no name: give it an entry point"):
        Stray.name  # noqa: B018


def test_listing_methods_imports_none_of_them():
    """``imuloco methods`` reads each method's summary from its source: neither numpy nor any
    method module (nor torch) is imported, which is what keeps it fast."""
    import subprocess
    import sys

    code = ("import sys\nfrom click.testing import CliRunner\nfrom imuloco.cli import cli\n"
            "res = CliRunner().invoke(cli, ['methods'])\nassert res.exit_code == 0\n"
            "heavy = [m for m in ('numpy', 'torch', 'scipy', 'sklearn', 'imuloco.methods.base')"
            " if m in sys.modules]\nassert not heavy, heavy\nprint(res.output)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=False)
    assert res.returncode == 0, res.stderr
    for name in NAMES:
        cls = method_class(name)
        online = "online" if cls.supports_online else "offline"
        assert f"[{online:>7}]  {cls.summary}" in res.stdout, name


def test_a_method_whose_extra_is_missing_is_listed_with_the_install_hint(monkeypatch):
    from importlib.metadata import PackageNotFoundError

    from imuloco.methods import registry

    real = registry.distribution

    def without_torch(name):
        if name == "torch":
            raise PackageNotFoundError(name)
        return real(name)

    monkeypatch.setattr(registry, "distribution", without_torch)
    info = registry.describe("learned")
    assert info.missing == "torch" and info.extra == "deep" and info.supports_online
    assert registry.describe("ridge").missing is None


# --- one constraint table per method, checked at construction (constructors only store)

@pytest.mark.parametrize("name", NAMES)
def test_each_constraint_names_a_parameter_and_the_defaults_pass(name):
    import inspect

    cls = method_class(name)
    takes = set(inspect.signature(cls.__init__).parameters) - {"self"}
    assert set(cls.param_constraints) <= takes, set(cls.param_constraints) - takes
    cls().check_params()  # the defaults lie within their own table


def test_a_method_built_directly_is_checked_as_it_is_built():
    """The constraint table is checked before ``__init__`` stores anything, for a class built
    directly as for one from the registry; ``set_params`` values are checked at fit."""
    from imuloco.errors import ParameterError
    from imuloco.methods.baselines import KnnPose

    with pytest.raises(ParameterError, match=r"method 'knn': parameter 'k' expects value") as e:
        KnnPose(k=0)
    assert e.value.key == "k"
    with pytest.raises(ParameterError, match="'window' expects a whole number"):
        KnnPose(3.5)  # positional arguments too
    with pytest.raises(ParameterError, match="has no parameter 'kk'"):
        KnnPose(kk=3)
    method = KnnPose().set_params(k=-1)  # stored: checked again when fitted
    with pytest.raises(ParameterError, match="'k'"):
        method.check_params()


def test_a_huge_whole_number_is_refused_by_its_range_not_an_overflow():
    """10**400 (JSON allows it) overflowed float() in the kind check (OverflowError)."""
    from imuloco.errors import ParameterError

    with pytest.raises(ParameterError, match="'window' expects value in"):
        get_method("ridge", window=10**400)
    with pytest.raises(ParameterError, match="'alpha' expects value in"):
        get_method("ridge", alpha=-10**400)
