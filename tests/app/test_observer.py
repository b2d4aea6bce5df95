"""The simulated participant as a forced-choice observer with a known answer (issue 57,
item 4), and a small sample of the benchmark that measures the procedures against it."""

import math

import numpy as np
import pytest

from app.observer import DISCRIMINATION, Observer, discrimination_from_report, draw_observer


def test_its_jnd_is_the_weber_fraction_it_is_right_75_percent_of_the_time():
    obs = Observer(jnd={"frequency": 0.2}, lapse=0.03)
    x75 = math.log10(1.2)  # by definition
    assert obs.threshold("frequency", 0.75, "log") == pytest.approx(x75, rel=1e-12)
    assert obs.p_right("frequency", x75) == pytest.approx(0.75, abs=1e-12)
    assert obs.threshold("frequency", 0.75, "dB") == pytest.approx(20 * x75)
    assert obs.threshold("frequency", 0.75, "linear", standard=100.0) == pytest.approx(20.0)
    assert obs.p_right("frequency", 0.0) == pytest.approx(0.5)  # a guess
    assert obs.p_right("frequency", 10.0) == pytest.approx(1 - 0.03)  # its lapses
    with pytest.raises(ValueError, match="out of this observer's reach"):
        obs.threshold("frequency", 0.98)
    with pytest.raises(KeyError, match="no JND for 'colour'"):
        obs.alpha("colour")


def test_it_answers_as_its_function_says():
    """4000 judgements at its JND: right 75 % of the time (binomial SE 0.7 points)."""
    obs = Observer(jnd={"frequency": 0.2}, lapse=0.02)
    rng = np.random.default_rng(5)
    right = [obs.judge("frequency", (120.0, 100.0), rng) == 0 for _ in range(4000)]
    assert np.mean(right) == pytest.approx(0.75, abs=0.025)
    right = [obs.judge("frequency", (100.0, 100.0 * 1.2 ** 3), rng) == 1 for _ in range(2000)]
    assert np.mean(right) > 0.95


def test_a_measured_jnd_replaces_the_assumed_one():
    report = {"analyses": [{"type": "threshold", "group": [
        {"parameter": "frequency", "criterion": 0.75, "weber_geomean": 0.11},
        {"parameter": "frequency", "criterion": 0.75, "weber_geomean": 0.44},
        {"parameter": "decay", "criterion": 0.794, "weber_geomean": 0.9}]}]}
    measured = discrimination_from_report(report)
    assert measured == {"frequency": pytest.approx(0.22)}  # geometric mean; 79 % left out
    rng = lambda: np.random.default_rng(np.random.SeedSequence([3, 1]))  # noqa: E731
    a, b = draw_observer(rng()), draw_observer(rng(), measured)
    assert b.jnd["frequency"] / a.jnd["frequency"] == pytest.approx(0.22 / DISCRIMINATION[
        "frequency"])
    assert b.jnd["decay"] == a.jnd["decay"]  # not measured: as assumed
    with pytest.raises(ValueError, match="75 % correct"):
        discrimination_from_report({"analyses": []})


@pytest.mark.slow
def test_the_benchmark_finds_the_observers_threshold_on_a_small_sample():
    """A small sample of `hapticlab bench thresholds` (the coverage study runs there, 200
    sessions a procedure): the estimates lie around the observers' true thresholds — a
    truth computed wrongly (a factor of 2) or an interval that never holds it would fail."""
    from benchmarks.thresholds import coverage

    for procedure, n in (("staircase", 8), ("questplus", 4)):
        r = coverage(procedure, n, seed=3)
        assert r["fitted"] == n
        assert abs(r["bias_log10"]) < 0.08 and r["rmse_log10"] < 0.15, r
        assert r["coverage"] >= 0.5 and r["profile_coverage"] >= 0.5, r
        assert 30 <= r["trials_median"] <= 60
