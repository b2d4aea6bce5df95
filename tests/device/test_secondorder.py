"""Closed-form second-order responses for every damping ratio."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from device.sim.secondorder import free_response, impulse_response, step_response

ZETAS = [0.0, 0.169, 1 - 1e-12, 1.0, 1 + 1e-12, 1.5, 10.0, 1e6]


@pytest.mark.slow
@pytest.mark.parametrize("zeta", ZETAS)
def test_matches_an_independent_ode_solution(zeta):
    wn = 2 * np.pi * 287.0  # the grasp model's nominal natural frequency
    t = np.linspace(0, 0.03, 61)
    x, v, _ = free_response(t, 1e-3, 0.1, wn, zeta)
    # reference: scipy's Radau, tolerances far below the asserted 1e-9
    sol = solve_ivp(lambda _t, y: [y[1], -2 * zeta * wn * y[1] - wn**2 * y[0]], (0, 0.03),
                    [1e-3, 0.1], t_eval=t, method="Radau", rtol=1e-13, atol=1e-16)
    scale = np.max(np.abs(sol.y[0]))
    assert np.max(np.abs(x - sol.y[0])) <= 1e-9 * scale
    assert np.max(np.abs(v - sol.y[1])) <= 1e-9 * np.max(np.abs(sol.y[1]))


@pytest.mark.parametrize("zeta", ZETAS)
def test_finite_at_long_times_and_extreme_damping(zeta):
    t = np.array([0.0, 1e-6, 1.0, 1e3, 1e6])
    x, v, a = free_response(t, 1.0, -1.0, 1e4, zeta)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(v)) and np.all(np.isfinite(a))
    assert x[0] == pytest.approx(1.0) and v[0] == pytest.approx(-1.0)


def test_continuous_across_critical_damping():
    t = np.linspace(0, 0.01, 50)
    below = free_response(t, 1e-3, 0.0, 1000.0, 1 - 1e-9)[0]
    at = free_response(t, 1e-3, 0.0, 1000.0, 1.0)[0]
    above = free_response(t, 1e-3, 0.0, 1000.0, 1 + 1e-9)[0]
    assert np.max(np.abs(below - at)) < 1e-12 and np.max(np.abs(above - at)) < 1e-12


def test_step_response_settles_at_force_over_stiffness():
    x, v, a = step_response([0.0, 10.0], mass=0.023, damping=14.0, stiffness=75_000.0, force=2.0)
    assert x[0] == 0.0 and v[0] == 0.0
    assert a[0] == pytest.approx(2.0 / 0.023)  # F/m at t = 0
    assert x[1] == pytest.approx(2.0 / 75_000.0, rel=1e-12)


def test_impulse_response_peak_and_sign():
    wn, zeta = 2 * np.pi * 100, 0.1
    t = np.linspace(0, 0.05, 5001)
    h = impulse_response(t, wn, zeta)
    wd = wn * np.sqrt(1 - zeta**2)
    assert h[0] == 0.0
    # first peak of e^(−ζωn t)·sin(ωd t)/ωd at tan(ωd t) = ωd/(ζωn)
    tp = np.arctan(wd / (zeta * wn)) / wd
    assert t[np.argmax(h)] == pytest.approx(tp, abs=1e-5)


@pytest.mark.parametrize("bad", [dict(wn=0.0, zeta=0.1), dict(wn=1.0, zeta=-0.1),
                                 dict(wn=np.nan, zeta=0.1), dict(wn=1.0, zeta=np.inf)])
def test_rejects_bad_parameters(bad):
    with pytest.raises(ValueError):
        free_response([0.0], 0.0, 0.0, **bad)
