"""Scenes as validated data."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from device import AccelSinusoid, ForceSinusoid, Material, Pulse, Ringing, Scene, SceneError
from device.scene import MAX_DAMPING, MAX_DECAY, MAX_GAIN, MAX_RINGING_HZ


def test_real_and_virtual_from_dict():
    wood = Scene.from_dict({"name": "wood", "material": {
        "stiffness": 70000, "damping": 40,
        "ringing": {"slope": -1500, "decay": 600, "frequency": 592}}})
    assert wood.is_real and wood.kind == "real"
    assert wood.material.ringing == Ringing(-1500.0, 600.0, 592.0)
    sin = Scene.from_dict({"name": "s", "spring": 680, "transient": {
        "kind": "sinusoid", "gain": 15.9, "decay_time": 0.055, "frequency": 36.2}})
    assert sin.kind == "sinusoid" and sin.spring == 680.0
    assert Scene.from_dict({"name": "k", "spring": 340}).kind == "spring"
    assert Scene.from_dict({"name": "n", "spring": 340, "transient": {"kind": "none"}}).kind \
        == "spring"


@pytest.mark.parametrize("data, fragment", [
    ({"name": "x", "spring": 680, "surface_heigth": 0}, "did you mean 'surface_height'"),
    ({"spring": 680}, "name: missing"),
    ({"name": "x", "spring": float("nan")}, "must be finite"),
    ({"name": "x", "spring": float("inf")}, "must be finite"),
    ({"name": "x", "spring": -1.0}, "spring: must be >= 0"),
    ({"name": "x", "spring": "stiff"}, "must be a number"),
    ({"name": "x", "spring": True}, "must be a number"),
    ({"name": "x"}, "needs either 'material'"),
    ({"name": "x", "spring": 1, "material": {"stiffness": 5}}, "cannot also have"),
    ({"name": "x", "material": {"stiffness": -5}}, "stiffness: must be > 0"),
    ({"name": "x", "material": {"stiffness": 5, "ringing": {"slope": 1, "decay": 1}}},
     "frequency: missing"),
    ({"name": "x", "spring": 1, "transient": {"kind": "wobble"}},
     "transient kind 'wobble' is not available"),
    ({"name": "x", "spring": 1, "transient": {"kind": "library"}}, "source: missing"),
    ({"name": "x", "spring": 1, "transient": {"kind": "library", "source": "w", "blend": "cubic"}},
     "blend: must be one of scale, nearest, linear"),
    ({"name": "x", "spring": 1, "transient": {"kind": "library", "source": "w",
                                              "attenuation": 0}}, "attenuation: must be > 0"),
    ({"name": "x", "spring": 1, "transient": {"gain": 1}}, "kind: missing"),
    ({"name": "x", "spring": 1, "transient": {"kind": "pulse", "gain": 1}},
     "duration: missing"),
    ({"name": "x", "spring": 1, "transient": {"kind": "pulse", "gain": 1, "duration": 0}},
     "duration: must be > 0"),
    ({"name": "x", "spring": 1, "transient": {"kind": "sinusoid", "gain": 1, "decay_time": 1,
                                              "frequency": 5, "cutoff": 2}}, "cutoff: must be <="),
    ({"name": "", "spring": 1}, "non-empty string"),
])
def test_bad_scene_names_the_field(data, fragment):
    with pytest.raises(SceneError) as err:
        Scene.from_dict(data, where="file.toml [samples.x]" if data.get("name") == "x" else None)
    assert fragment in str(err.value)
    if data.get("name") == "x":
        assert str(err.value).startswith("file.toml [samples.x]")


def test_pulse_table():
    t = Pulse(5.7, 0.020).unit_table(10_000, 0.05)
    assert len(t) == 200 and set(t) == {5.7}


def test_force_sinusoid_table_matches_formula():
    tr = ForceSinusoid(15.9, 0.055, 36.2)
    tab = tr.unit_table(10_000, 0.05)
    # length: d·ln(1/cutoff) = 0.055·ln 100 = 0.2533 s -> 2533 ticks
    assert len(tab) == math.ceil(0.055 * math.log(100) * 10_000)
    k = 123
    t = k / 10_000
    assert tab[k] == pytest.approx(15.9 * math.exp(-t / 0.055) * math.sin(2 * math.pi * 36.2 * t),
                                   rel=1e-12)


def test_accel_sinusoid_is_mass_times_q():
    tr = AccelSinusoid(-150.0, 80.0, 100.0)
    tab = tr.unit_table(10_000, 0.055)
    t = 25 / 10_000  # quarter period at 100 Hz: sin = 1
    # F = m·A·v_n·e^(−Bt) with v_n = −1 m/s: 0.055·150·e^(−0.2) = 6.7547... N
    assert tab[25] == pytest.approx(0.055 * 150 * math.exp(-80 * t), rel=1e-12)
    assert tab[25] > 0  # negative slope pushes out of the surface first


finite = st.floats(min_value=1e-3, max_value=1e6, allow_nan=False)


def upto(bound):
    """Positive values up to a scene's stated bound (device.scene.MAX_*), the bound included."""
    return st.floats(min_value=1e-3, max_value=bound, allow_nan=False)


@given(name=st.text(min_size=1, max_size=12), h=st.floats(-0.5, 0.5), k=finite,
       b=upto(MAX_DAMPING), ring=st.one_of(st.none(), st.tuples(
           st.floats(-1e5, 1e5), upto(MAX_DECAY), upto(MAX_RINGING_HZ))))
def test_real_scene_round_trip(name, h, k, b, ring):
    mat = {"stiffness": k, "damping": b}
    if ring is not None:
        mat["ringing"] = {"slope": ring[0], "decay": ring[1], "frequency": ring[2]}
    s = Scene.from_dict({"name": name, "surface_height": h, "material": mat})
    assert Scene.from_dict(s.to_dict()) == s


@given(k=st.floats(0, 1e5), kind=st.sampled_from(["pulse", "sinusoid", "q_sinusoid"]),
       a=upto(MAX_GAIN), d=st.floats(1e-3, 1.0), f=st.floats(1.0, 2000.0))
def test_virtual_scene_round_trip(k, kind, a, d, f):
    tr = {"pulse": {"kind": "pulse", "gain": a, "duration": d},
          "sinusoid": {"kind": "sinusoid", "gain": a, "decay_time": d, "frequency": f},
          "q_sinusoid": {"kind": "q_sinusoid", "slope": -a, "decay": 1 / d, "frequency": f}}[kind]
    s = Scene.from_dict({"name": "v", "spring": k, "transient": tr})
    assert Scene.from_dict(s.to_dict()) == s
    assert s.kind == kind


def test_material_defaults():
    assert Material(220.0).damping == 0.0
