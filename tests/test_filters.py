"""Resampling onto a uniform grid: as many samples as the recording at its mean rate, the
grid's ends, and the sample count past float rounding of long recordings."""

from __future__ import annotations

import numpy as np
import pytest

from imuloco.ops.filters import _grid_samples, resample_linear, resample_uniform


def _jittered(seed: int, n: int, t0: float, rate: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return t0 + np.cumsum(rng.uniform(0.5, 1.5, n)) / rate


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("t0", [0.0, 37.125, 1.7e9])  # the last: Unix time stamps
def test_at_the_mean_rate_the_grid_has_as_many_samples(seed, t0):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 200_000))
    times = _jittered(seed, n, t0, rng.uniform(20, 500))
    x = rng.normal(size=(n, 2))
    rate = (n - 1) / (times[-1] - times[0])
    out = resample_uniform(times, x, rate)
    assert np.array_equal(out, resample_linear(times, x, times[0] + np.arange(n) / rate))


def test_a_line_is_resampled_exactly_and_the_grid_ends_at_the_last_time():
    times = _jittered(0, 1000, 12.0, 99.3)
    x = np.stack([3.0 - 2.0 * times, times], axis=1)
    for rate in (100.0, 50.0, 99.3, 7.0):
        out = resample_uniform(times, x, rate)
        grid = times[0] + np.arange(len(out)) / rate
        assert np.allclose(out[:, 1], grid, rtol=0, atol=1e-9)
        assert np.allclose(out[:, 0], 3.0 - 2.0 * grid, rtol=0, atol=1e-9)
        assert grid[-1] <= times[-1] + 1e-9 < grid[-1] + 1 / rate


def test_a_whole_number_of_periods_keeps_its_last_sample():
    # 0.01 s is not a float: the span times 100 Hz comes out a rounding error off 1000
    times = 5.0 + np.arange(1001) * 0.01
    assert len(resample_uniform(times, np.zeros(1001), 100.0)) == 1001
    assert resample_uniform(np.array([0.0, 1.0]), np.array([0.0, 1.0]), 2.0).tolist() == \
        [0.0, 0.5, 1.0]


def test_a_long_recording_at_its_mean_rate_keeps_every_sample():
    """Above 2**24 samples the mean rate times the span can fall an ulp (3.7e-9) short of a
    whole number: an absolute 1e-9 allowance would drop the last sample."""
    n, span = 16_862_987, 131650.23637281673  # 36.6 h at 128 Hz
    k = span * ((n - 1) / span)
    assert int(np.floor(k + 1e-9)) + 1 == n - 1  # the case is one
    assert _grid_samples(span, (n - 1) / span) == n
