"""The measuring parts of ``hapticlab bench causes``: distances the participant model
would compute, ranks, the sample variants it tries, and one real feel of a sample."""

import math

import numpy as np
import pytest

from benchmarks import causes
from device import Material, Scene, Support


def test_distances_scale_by_jnd_and_an_infinite_jnd_leaves_a_feature_out():
    ref = np.array([0.0, 0.0, 0.0, 0.0])
    felt = {"a": np.array([1.0, 1.2, 0.0, 0.0]), "b": np.array([0.0, 0.0, 0.5, np.nan])}
    jnd = np.array([0.5, 0.6, 0.5, 0.6])
    d = causes.distances(felt, ref, jnd)
    assert d["a"] == pytest.approx(math.hypot(2.0, 2.0)) and d["b"] == pytest.approx(1.0)
    assert causes.ranks(d) == {"b": 1, "a": 2}
    d = causes.distances(felt, ref, np.array([math.inf, 0.6, 0.5, 0.6]))
    assert d["a"] == pytest.approx(2.0)


def test_a_variant_keeps_the_supports_damping_ratio():
    base = Scene("wof", material=Material(70_000.0, 20.0, mass=0.006,
                                          support=Support(350.0, 3.0)))
    v = causes._variant(base, 0.024, 10.0).material
    assert (v.mass, v.support.stiffness) == (0.024, 3500.0)

    def zeta(m):
        return m.support.damping / (2 * math.sqrt(m.support.stiffness * m.mass))

    assert zeta(v) == pytest.approx(zeta(base.material))
    assert (v.stiffness, v.damping) == (70_000.0, 20.0)  # the contact is untouched


def test_a_real_sample_is_felt_and_a_stiffer_support_stops_sooner():
    """Measured on the simulated device (seed 1, 2 windows): a 6-g plate on 35 kN/m of
    foam stops the stylus sooner than on 350 N/m (the ``stop`` feature is a log time)."""
    base = Scene("wof", material=Material(70_000.0, 20.0, mass=0.006,
                                          support=Support(350.0, 3.0)))
    soft = causes.feel(base, [1], windows=2)
    stiff = causes.feel(causes._variant(base, 0.006, 100.0), [1], windows=2)
    assert np.all(np.isfinite(soft)) and np.all(np.isfinite(stiff))
    assert stiff[0] < soft[0] - 1.0  # e^1: the stop at least 2.7× sooner
