"""The grasp-force model of contact vibrations (SPEC §3)."""

import numpy as np
import pytest

from device import Scene, SceneError
from device.matching.grasp import (
    PUBLISHED,
    GraspRig,
    _model_accel,
    fit_percent,
    identify_grasp,
    identify_impact,
    peak_gain,
)


@pytest.fixture(scope="module")
def noisy():
    return GraspRig().impacts(100, seed=1)


def test_fit_percent_definition():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0)
    # ‖y − ŷ‖ = 1, ‖y − ȳ‖ = √5 → 100·(1 − 1/√5) = 55.28 %
    assert fit_percent(y, y + np.array([1.0, 0, 0, 0])) == pytest.approx(100 * (1 - 5**-0.5))


@pytest.mark.parametrize("K, T, zeta", [(1 / 75_000, 5.5e-4, 0.17), (1 / 55_000, 5.4e-4, 0.12),
                                        (1e-5, 3e-4, 0.05)])
def test_gain_from_the_model_peak_round_trips(K, T, zeta):
    """Synthetic transients of K·s²/(T²s² + 2ζTs + 1) driven by a contact pulse through the
    sensor: the gain derivation returns K exactly (the model is linear in K)."""
    force = np.zeros(300)
    force[10:15] = np.sin(np.pi * np.arange(5) / 4) * 2.0
    accel = _model_accel(T * T / K, 2 * zeta * T / K, 1 / K, force, 10_000, 1000)
    assert peak_gain(accel, force, T, zeta, 10_000, 1000) == pytest.approx(K, rel=1e-12)


def test_noise_free_impact_identification():
    """Without noise: manual estimates within 15 %, least squares and recursive within 6 %
    (measured up to 10.8 %, 4.7 %, 4.8 %). The floor is the force sensor: the 0.4-ms
    contact pulse spans four samples, and a force taken as linear between samples
    misstates its impulse by a few percent depending on where the pulse falls between
    samples, which scales m, c and k together."""
    rig = GraspRig(accel_noise=0.0, force_noise=0.0)
    for imp in rig.impacts(5, seed=4):
        fit = identify_impact(imp)
        for est, tol in (("manual", 0.15), ("ls", 0.06), ("rls", 0.06)):
            np.testing.assert_allclose(getattr(fit, est), imp.true, rtol=tol, err_msg=est)


def test_paper_formula_differs_by_the_threshold():
    """ζ = 1/√((π·F_d·T_s)² + 1) assumes the envelope at e^(−2) = 13.5 %; measured at 15 % it
    takes σ = 2/T_s instead of ln(1/0.15)/T_s, a ζ about 5 % (2/ln(1/0.15) = 1.054) higher
    than the exact relation (for light damping, where ζ ≈ σ/ω_d)."""
    imp = GraspRig(accel_noise=0.0, force_noise=0.0).impacts(1, seed=2)[0]
    exact = identify_impact(imp)
    paper = identify_impact(imp, paper_formula=True)
    assert paper.zeta / exact.zeta == pytest.approx(2 / np.log(1 / 0.15), rel=0.02)


@pytest.mark.parametrize("estimate, tol_i, tol_s", [("ls", 0.03, 0.15), ("rls", 0.05, 0.25),
                                                    ("manual", 0.15, 0.30)])
def test_recovers_the_published_relations_from_100_noisy_impacts(noisy, estimate, tol_i, tol_s):
    """Tolerances on intercepts / slopes (worst seen over 6 seeds: ls 1.7 % / 10.3 %,
    rls 2.8 % / 17.2 %, manual 10.6 % / 19.5 %)."""
    r = identify_grasp(noisy, estimate=estimate)
    for name, (i_pub, s_pub) in (("m", PUBLISHED.m), ("c", PUBLISHED.c), ("k", PUBLISHED.k)):
        assert r[name]["intercept"] == pytest.approx(i_pub, rel=tol_i), name
        assert r[name]["slope"] == pytest.approx(s_pub, rel=tol_s), name
    assert r["fit_percent"]["by_estimate"][estimate] > 80.0  # the paper: 69.8–81.4 %


def test_grasp_transient_scales_with_grasp_force():
    tables = [Scene.from_dict({"name": "g", "spring": 500.0, "transient": {
        "kind": "grasp", "grasp_force": fg}}).transient.unit_table(10_000, 0.055)
        for fg in (2.0, 10.0, 20.0)]
    peaks = [np.max(np.abs(t)) for t in tables]
    assert peaks[0] < peaks[1] < peaks[2]
    with pytest.raises(SceneError, match="outside the model's range"):
        Scene.from_dict({"name": "g", "spring": 1.0,
                         "transient": {"kind": "grasp", "grasp_force": 80.0}})
    with pytest.raises(ValueError, match="outside the model's range"):
        PUBLISHED.at(100.0)
