"""The simulated tapper's intended motion."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from device.sim.tapper import Tapper


def test_speeds_follow_the_population_distribution():
    plan = Tapper().plan(np.random.default_rng(0), 2000.0)
    v = plan.speeds
    assert len(v) > 2000
    # N(0.11, 0.033) truncated at 0.02 and 0.40 (3σ): mean and SD barely move
    assert v.mean() == pytest.approx(0.11, abs=0.003)
    assert v.std() == pytest.approx(0.033, abs=0.003)
    assert v.min() >= 0.02 and v.max() <= 0.40


@given(v=st.floats(0.02, 0.4), top=st.floats(0.002, 0.05), press=st.floats(0.0, 0.01),
       seed=st.integers(0, 2**32 - 1))
def test_reference_is_continuous_and_consistent(v, top, press, seed):
    tap = Tapper(velocity_mean=v, velocity_sd=0.0, top=top, press_depth=press)
    plan = tap.plan(np.random.default_rng(seed), 3.0, surface_height=0.01)
    dt = 1e-5
    t = np.arange(0, 3.0, dt)
    z, vel, acc = plan.reference(t)
    assert np.all(np.isfinite(z)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(acc))
    vmax = max(v, (top + press) * np.pi / (2 * tap.rise_time))
    assert np.max(np.abs(np.diff(z))) <= vmax * dt * (1 + 1e-6) + 1e-12  # no jumps
    # velocity is the derivative of position (central differences), except at the one
    # intended step per stroke: the stop at the bottom
    dz = (z[2:] - z[:-2]) / (2 * dt)
    off = np.abs(dz - vel[1:-1]) > 1e-3 * vmax + 1e-9
    assert off.sum() <= 2 * len(plan.strokes)
    # acceleration is the derivative of velocity away from phase boundaries
    dv = (vel[2:] - vel[:-2]) / (2 * dt)
    amax = np.max(np.abs(acc))
    assert (np.abs(dv - acc[1:-1]) > 1e-3 * amax + 1e-9).sum() <= 8 * len(plan.strokes)
    assert z.max() <= 0.01 + top + 1e-12 and z.min() >= 0.01 - press - 1e-12


def test_speeds_can_be_given():
    plan = Tapper().plan(np.random.default_rng(0), 5.0, speeds=[0.05, 0.2])
    assert list(plan.speeds[:4]) == [0.05, 0.2, 0.05, 0.2]


@pytest.mark.parametrize("kw", [dict(velocity_mean=0), dict(top=-1), dict(dwell=(0.2, 0.1)),
                                dict(velocity_min=0.5, velocity_max=0.1)])
def test_bad_parameters_are_refused(kw):
    with pytest.raises(ValueError, match="tapper parameter"):
        Tapper(**kw)
