"""The grasp-force model of contact vibrations (SPEC §3)."""

import re

import numpy as np
import pytest

from device import Scene, SceneError
from device.matching.grasp import (
    PUBLISHED,
    TISSUE,
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


@pytest.mark.slow
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


def test_a_tissue_mode_of_no_mass_is_the_published_handle():
    """The tissue rig's plant with a vanishing tissue mass gives the published handle's
    impact (to 1e-6 of its peak); a real one changes it."""
    rng = np.random.default_rng(3)
    plain = GraspRig(accel_noise=0.0, force_noise=0.0).impact(rng, 8.0, 1.5)
    rng = np.random.default_rng(3)
    none = GraspRig(accel_noise=0.0, force_noise=0.0, tissue=(1e-12, 2.0, 0.2)).impact(
        rng, 8.0, 1.5)
    rng = np.random.default_rng(3)
    some = GraspRig(accel_noise=0.0, force_noise=0.0, tissue=TISSUE).impact(rng, 8.0, 1.5)
    peak = np.max(np.abs(plain.accel))
    assert np.max(np.abs(none.accel - plain.accel)) < 1e-6 * peak
    assert np.max(np.abs(some.accel - plain.accel)) > 0.05 * peak
    for bad in ((0.0, 2.0, 0.2), (0.1, -1.0, 0.2), (0.1, 2.0, float("nan")), (0.1, 2.0),
                ("a", 2.0, 0.2)):
        with pytest.raises(ValueError, match="tissue"):
            GraspRig(tissue=bad)
    assert GraspRig(tissue=("0.12", "2", "0.2")).tissue == (0.12, 2.0, 0.2)


def test_the_modal_response_is_scipys_state_space_simulation():
    """The rig's mode-by-mode response of the 5-state tissue plant against scipy's dlsim of
    the same ZOH-discretized system (a step-by-step state recursion), on a random force."""
    from scipy import signal

    from device.matching.grasp import _plant_with_tissue, _zoh_response

    A, B, C, D = _plant_with_tissue(0.02, 12.0, 70_000.0, TISSUE, 1_000.0)
    dt = 1e-5
    u = np.random.default_rng(0).normal(size=400)
    ours = _zoh_response(A, B, C, D, dt, u)
    _, ref, _ = signal.dlsim(signal.cont2discrete((A, B[:, None], C[None, :], np.array([[D]])),
                                                  dt, method="zoh"), u)
    assert np.max(np.abs(ours - ref[:, 0])) <= 1e-9 * np.max(np.abs(ref))


def _foh_by_hand(m, c, k, rate_hz, rc_hz):
    """The first-order hold derived by hand (what grasp.py held before scipy's): with the
    exponential of [[A, B, 0], [0, 0, 1], [0, 0, 0]]·T, x[k+1] = Φx[k] + (Γa − Γb/T)·u[k]
    + (Γb/T)·u[k+1], as a transfer function in z."""
    import warnings

    from scipy import signal
    from scipy.linalg import expm

    from device.matching.grasp import _plant

    A, B, C, D = _plant(m, c, k, rc_hz)
    n, T = A.shape[0], 1.0 / rate_hz
    M = np.zeros((n + 2, n + 2))
    M[:n, :n], M[:n, n], M[n, n + 1] = A, B, 1.0
    E = expm(M * T)
    Phi, Ga, Gb = E[:n, :n], E[:n, n], E[:n, n + 1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", signal.BadCoefficients)
        n0, den = signal.ss2tf(Phi, (Ga - Gb / T)[:, None], C[None, :], np.array([[D]]))
        n1, _ = signal.ss2tf(Phi, (Gb / T)[:, None], C[None, :], np.zeros((1, 1)))
    return n0[0] + np.append(n1[0][1:], 0.0), den


@pytest.mark.parametrize("rate_hz, rc_hz", [(10_000.0, None), (10_000.0, 1_000.0),
                                             (2_000.0, 300.0), (100_000.0, 1_000.0)])
def test_the_models_first_order_hold_is_the_hand_derived_one(rate_hz, rc_hz):
    """scipy's first-order hold (cont2discrete, foh) gives the response the hand derivation
    gave, on a force linear between samples of a random walk, to 1e-9 of its peak."""
    from scipy import signal

    from device.matching.grasp import foh_filter

    m, c, k = 0.023, 14.0, 75_000.0
    force = np.cumsum(np.random.default_rng(3).normal(size=3000))
    ours = signal.lfilter(*foh_filter(m, c, k, rate_hz, rc_hz), force)
    ref = signal.lfilter(*_foh_by_hand(m, c, k, rate_hz, rc_hz), force)
    assert np.max(np.abs(ours - ref)) <= 1e-9 * np.max(np.abs(ref))


@pytest.mark.slow
def test_impacts_with_a_mode_the_model_lacks_fit_as_the_papers_and_bias_the_relations():
    """The tissue rig (the published handle with TISSUE, 60 impacts, seed 1) is not a round
    trip: the manual fit scores in the paper's manual range (69.8–79.6 %; measured 78.0,
    least squares 80.9, recursive 77.1) where the published rig scores 86–89, and the
    relations come out biased by the unmodelled mode (measured: m +8.6 %, c +6.1 %, k −6.2 %
    at no grasp), the slopes keep their sign. Fewer than 3 impacts are refused by name."""
    r = identify_grasp(GraspRig(tissue=TISSUE).impacts(60, seed=1))
    fit = r["fit_percent"]["by_estimate"]
    assert 69.8 <= fit["manual"] <= 79.6, fit
    assert fit["ls"] < 84.0 and fit["rls"] < 84.0, fit
    plain = identify_grasp(GraspRig().impacts(60, seed=1))["fit_percent"]["by_estimate"]
    assert all(plain[e] > fit[e] + 4.0 for e in fit), (plain, fit)
    for name, (i_pub, s_pub) in (("m", PUBLISHED.m), ("c", PUBLISHED.c), ("k", PUBLISHED.k)):
        err = r[name]["intercept"] / i_pub - 1.0
        assert 0.03 < abs(err) < 0.15, (name, err)  # biased, and by a few per cent
        assert np.sign(r[name]["slope"]) == np.sign(s_pub), name
    with pytest.raises(ValueError, match="2 impacts: .* fewer than 3"):
        identify_grasp(GraspRig().impacts(2, seed=1))


def _grasp_table(fg: float):
    return Scene.from_dict({"name": "g", "spring": 500.0, "transient": {
        "kind": "grasp", "grasp_force": fg}}).transient.table(10_000, 0.055)


@pytest.mark.parametrize("fg", [0.0, 5.0, 20.0])
def test_the_grasp_transient_is_the_papers_equation_solved(fg):
    """Against m·ẍ + c·ẋ + k·x = F_g, x(0) = 0, ẋ(0) = −v integrated by scipy's DOP853
    (not the closed form the scene uses), at the table's two speeds and one the device
    blends: within 1e-6 of the peak."""
    from scipy.integrate import solve_ivp

    m, c, k = PUBLISHED.at(fg)
    table = _grasp_table(fg)
    t = np.arange(table.forces.shape[1]) / 10_000
    for v in (0.02, 0.11, 0.40):
        sol = solve_ivp(lambda _t, y: [y[1], (fg - c * y[1] - k * y[0]) / m], (0, t[-1]),
                        [0.0, -v], method="DOP853", t_eval=t, rtol=1e-12, atol=1e-15)
        accel = (fg - c * sol.y[1] - k * sol.y[0]) / m
        played = table.force_at(v) / 0.055
        np.testing.assert_allclose(played, accel, rtol=0, atol=1e-6 * np.max(np.abs(accel)))


def test_the_grasp_transients_peak_grows_about_linearly_with_grasp_force():
    """The paper: the peak transient amplitude grows about linearly with grasp force. At
    the tapper's median 0.11 m/s, 2 to 20 N: Pearson r > 0.99 (0.994 computed) and ×6.2
    from 2 to 20 N (before the grasp drove the model, +0.8 % from 0 to 20 N)."""
    fgs = np.arange(2.0, 20.5, 2.0)
    peaks = np.array([np.max(np.abs(_grasp_table(fg).force_at(0.11))) for fg in fgs])
    assert np.all(np.diff(peaks) > 0)
    assert np.corrcoef(fgs, peaks)[0, 1] > 0.99
    assert peaks[-1] / peaks[0] > 5.0


def test_a_grasp_force_outside_the_models_range_is_refused():
    with pytest.raises(SceneError, match="outside the model's range"):
        Scene.from_dict({"name": "g", "spring": 1.0,
                         "transient": {"kind": "grasp", "grasp_force": 80.0}})
    with pytest.raises(ValueError, match="outside the model's range"):
        PUBLISHED.at(100.0)


def test_an_unattenuated_grasp_transient_is_refused_by_what_is_played_and_an_attenuated_fits():
    """9–70 N at 0.11 m/s on a 55-g stylus: the wire refuses a linear table beyond ±32.767
    N (never clips it), and 0.04 of it carries 5 N of grasp within a 3-N device."""
    from device.serial.backend import _wire_table

    full = _grasp_table(5.0)
    with pytest.raises(SceneError, match=r"linear table carries at most ±32.767 N"):
        _wire_table(full, "here")
    soft = Scene.from_dict({"name": "g", "spring": 500.0, "transient": {
        "kind": "grasp", "grasp_force": 5.0, "attenuation": 0.04}}).transient.table(10_000, 0.055)
    v, q = _wire_table(soft, "here")
    assert list(v) == [0.02, 0.40] and q.shape == soft.forces.shape
    np.testing.assert_allclose(soft.force_at(0.11), 0.04 * full.force_at(0.11))
    assert np.max(np.abs(soft.force_at(0.11))) < 3.0


def test_the_protocol_check_names_the_grasp_transients_played_peak(tmp_path):
    """The check at the design speed uses the played table (speed and grasp shares): at 20
    N of grasp, 0.055 kg × 1,272 m/s² = 70 N, not the speed's share alone (9 N)."""
    from device.sim.backend import SimDevice
    from protocols import load_protocol
    from protocols.loader import ProtocolError

    text = load_protocol("realism").text.replace(
        'scene.transient = { kind = "pulse", gain = 5.7, duration = 0.020 }',
        'scene.transient = { kind = "grasp", grasp_force = 20.0 }', 1)
    assert "grasp_force = 20.0" in text
    path = tmp_path / "grasp.toml"
    path.write_text(text)
    with pytest.raises(ProtocolError, match=r"'pulse_firm': transient peak ([\d.]+) N at 0.11 m/s"
                       ) as err:
        load_protocol(path, SimDevice().info)
    played = float(re.search(r"peak ([\d.]+) N", str(err.value)).group(1))
    assert played == pytest.approx(np.max(np.abs(_grasp_table(20.0).force_at(0.11))), abs=0.01)
    assert played > 65.0  # the speed's share alone was 9.2 N
