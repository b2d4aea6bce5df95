"""Real samples are passive physics: a block that moves, energy that is only ever stored or
lost, the measured ringing reproduced by the model, and a guard against blow-ups."""

import math

import numpy as np
import pytest

from device import Material, Ringing, Scene, SceneError, Support
from device.matching.library import record_taps, segment_taps
from device.matching.vibration import fit_vibration
from device.sim import kernel as K
from device.sim.audit import energy_audit
from device.sim.backend import SimDevice
from device.sim.plant import block_model, contact_modes
from device.sim.tapper import Tapper
from protocols import BUILTIN, load_protocol

TABLE1 = {"wood": (-1500.0, 600.0, 592.0, 0.026, 70_000.0),  # A, B, f; block mass, K
          "aluminum": (-100_000.0, 1500.0, 1153.0, 0.116, 500_000.0)}


def real_samples():
    """(protocol/sample, scene) of every real sample of the built-in protocols, each once."""
    out, seen = [], set()
    for name in BUILTIN:
        for sid, s in load_protocol(name).samples.items():
            if s.scene.is_real and s.scene.material not in seen:
                seen.add(s.scene.material)
                out.append((f"{name}/{sid}", s.scene))
    return out


@pytest.mark.parametrize("material, field, words", [
    (dict(stiffness=1e4, mass=0.02), "mass", "needs what it rests on"),
    (dict(stiffness=1e4, support=Support(300.0)), "mass", "give the block's 'mass'"),
    (dict(stiffness=1e4, mass=0.02, support=Support(300.0), ringing=Ringing(-1, 10, 100)),
     "support", "not both"),
    (dict(stiffness=1e4, mass=0.0, support=Support(300.0)), "mass", "must be > 0"),
    (dict(stiffness=1e4, mass=50.0, support=Support(300.0)), "mass", "must be <= 5"),
])
def test_a_block_is_described_completely_or_refused(material, field, words):
    with pytest.raises(SceneError) as err:
        Material(**material)
    assert err.value.field == field and words in str(err.value)


@pytest.mark.parametrize("decay", [0.0, -5.0])
def test_a_ringing_that_never_dies_out_is_a_scene_error(decay):
    with pytest.raises(SceneError) as err:
        Scene.from_dict({"name": "x", "material": {"stiffness": 1e4, "mass": 0.02, "ringing": {
            "slope": -100.0, "decay": decay, "frequency": 100.0}}}, where="f.toml [samples.x]")
    msg = str(err.value)
    assert msg.startswith("f.toml [samples.x]") and "decay: must be > 0" in msg
    assert "\n" not in msg


def test_a_ringing_blocks_damping_is_derived_not_given():
    with pytest.raises(SceneError, match="damping: a ringing block's contact damping is derived"):
        Scene.from_dict({"name": "x", "material": {"stiffness": 7e4, "damping": 20, "mass": 0.026,
                                                   "ringing": {"slope": -1500, "decay": 600,
                                                               "frequency": 592}}})


def test_a_ringing_without_a_block_is_data_but_the_simulator_asks_for_the_mass():
    """Older protocol copies give a ringing without a mass: they still load (the analysis
    reads them), and the simulator says what it needs."""
    scene = Scene.from_dict({"name": "w", "material": {"stiffness": 7e4, "damping": 40, "ringing": {
        "slope": -1500, "decay": 600, "frequency": 592}}})
    dev = SimDevice()
    with pytest.raises(SceneError) as err:
        dev.check_scene(scene)
    assert "scene 'w'" in str(err.value) and "'mass' [kg]" in str(err.value)


@pytest.mark.parametrize("name", ["wood", "aluminum"])
def test_the_derived_block_rings_as_table_1_and_presses_as_k(name):
    """The contact mode is at −B ± i·2πf to solver precision, and pressing the block feels
    the given K (contact and support in series)."""
    A, B, f, mass, k = TABLE1[name]
    b = block_model(Material(k, ringing=Ringing(A, B, f), mass=mass))
    lam = contact_modes((b.contact_stiffness, b.contact_damping), (b.mass, b.support))
    ring = lam[np.argmin(np.abs(lam - complex(-B, 2 * math.pi * f)))]
    assert ring.imag / (2 * math.pi) == pytest.approx(f, rel=1e-6)
    assert -ring.real == pytest.approx(B, rel=1e-6)
    assert b.static_stiffness == pytest.approx(k, rel=1e-9)
    m2 = 0.11  # stylus and hand
    mu = m2 * mass / (m2 + mass)
    assert b.contact_damping <= 2 * 0.5 * math.sqrt(b.contact_stiffness * mu)  # elastic


def test_no_passive_block_rings_faster_than_its_contact_allows():
    with pytest.raises(SceneError) as err:  # a 1-g block cannot ring at 20 Hz on 70 kN/m
        block_model(Material(70_000.0, ringing=Ringing(-100.0, 5.0, 20.0), mass=0.001))
    assert err.value.field == "ringing" and "no passive block" in str(err.value)


@pytest.mark.parametrize("name, speed, spread", [
    ("wood", 0.03, 0.2), ("wood", 0.06, 0.2), ("aluminum", 0.03, 0.2), ("aluminum", 0.06, 0.2),
    ("wood", 0.06, 0.0), ("aluminum", 0.06, 0.0)])
def test_taps_on_the_simulated_block_fit_table_1_within_ten_percent(name, speed, spread):
    """The accelerometer's taps, fitted as Q(t) = A·v·e^(−Bt)·sin(2πft) the way Table 1 was
    (SPEC §2): f and B within 10 % at tap speeds where the hand's ~1.2 N keeps the stylus
    on the block. Faster taps make the ringing's own force open the contact (chatter), so
    the fitted decay reads higher there (README, "Real samples"). Taps at one constant
    speed (``spread`` 0) fit too: they once failed, every tap alike, with "the taps hold no
    decaying vibration" (issue 34). Every such tap on wood builds its ringing up over the
    first cycle, so the fit takes them from their peaks (``start``) and B includes the
    contact's own decay after it: measured +12.5 %, so 15 % there."""
    A, B, f, mass, k = TABLE1[name]
    scene = Scene(name, material=Material(k, ringing=Ringing(A, B, f), mass=mass))
    fits = []
    for seed in (2, 3):
        tapper = Tapper(velocity_mean=speed, velocity_sd=spread * speed,
                        velocity_min=0.5 * speed, velocity_max=1.5 * speed)
        taps = segment_taps(record_taps(SimDevice(seed=seed, tapper=tapper), scene, 4))
        fits.append(fit_vibration(taps, 10_000, band=(0.5 * f, 2 * f), accel_bandwidth=1000))
    got_f = np.mean([x.frequency for x in fits])
    got_b = np.mean([x.decay for x in fits])
    assert got_f == pytest.approx(f, rel=0.10)
    assert got_b == pytest.approx(B, rel=0.10 if spread else 0.15)
    # taps spread in speed decay from their first extremum; wood's, at one speed, all build
    # up first (aluminum's do not)
    if spread or name == "aluminum":
        assert all(x.start == "first" for x in fits)
    else:
        assert all(x.start == "peak" for x in fits)
    assert all(x.slope < 0 for x in fits)  # the first push is out of the surface


def test_thirty_seconds_on_each_real_block_of_the_factorial_study():
    """10 kHz, taps up to 0.4 m/s: every state finite, no contact faster than 1 m/s, and the
    stylus never moves faster than the fastest tap intended (aluminum used to throw it out
    2.9× faster at every bounce: 1e30 m/s after 5 s)."""
    proto = load_protocol("factorial")
    for sid in ("rubber-real", "wood-real", "aluminum-real"):
        tapper = Tapper(sweep=tuple(np.linspace(0.02, 0.4, 20)))
        dev = SimDevice(seed=4, tapper=tapper)
        dev.load_scene(proto.samples[sid].scene)
        dev.home()
        res = dev.run_window(30.0, from_first_contact=False)
        tr = res.traces
        assert not res.faults, sid
        for ch in ("true_position", "true_velocity", "true_accel", "position"):
            assert np.all(np.isfinite(tr[ch])), (sid, ch)
        assert res.velocities.max() < 1.0, sid
        assert -tr["true_velocity"].min() <= 0.4 * 1.02, sid
        assert res.energy["out"] < res.energy["in"], sid


@pytest.mark.slow
@pytest.mark.parametrize("rate", [1_000, 10_000, 20_000])
def test_energy_audit_every_real_sample_is_passive(rate):
    for name, scene in real_samples():
        row = energy_audit(scene, rate, window_s=30.0)
        assert row.finite and row.passive, (name, row)
        assert row.energy_out_j < row.energy_in_j and row.max_restitution < 1.0, (name, row)
        assert row.max_contact_speed <= row.max_tap_speed * 1.02, (name, row)
        # nothing leaves faster than the fastest arrival (aluminum measured 0.168 of 0.402
        # m/s at 10 kHz; it used to leave 2.9x faster than it came)
        assert row.max_rebound_speed < row.max_contact_speed, (name, row)


def test_the_audit_calls_a_sampled_spring_active_and_says_why():
    """A held (ZOH) spring returns more than it took — the verdict names the cause, and the
    lossless real contact with the same stiffness does not."""
    spring = energy_audit(Scene("k", spring=680.0), 1_000, window_s=10.0)
    assert spring.energy_out_j > spring.energy_in_j and not spring.passive
    assert "zero-order hold" in spring.verdict
    lossless = energy_audit(Scene("k_real", material=Material(680.0, 0.0)), 1_000,
                            window_s=10.0)
    assert lossless.energy_out_j <= lossless.energy_in_j * (1 + 1e-6) and lossless.passive


def test_a_blow_up_latches_a_named_fault_and_ends_the_window():
    """Whatever made the state leave every physical bound (here: set by hand, as no scene
    does it any more), the window ends with a 'diverged' fault, output zero, traces finite."""
    dev = SimDevice(seed=1)
    dev.load_scene(Scene("k", spring=680.0))
    dev.home()
    dev._x[K.V2] = 25.0  # 25 m/s: no hand taps like that
    res = dev.run_window(5.0, from_first_contact=False)
    assert res.faults and res.faults[0].code == "diverged"
    assert "physical bound" in res.faults[0].message and dev.fault.code == "diverged"
    assert len(res.traces["t"]) <= 2 and np.all(np.isfinite(res.traces["current"]))
    with pytest.raises(Exception, match="diverged"):
        dev.home()  # latched until cleared
    dev.clear_fault()
    dev.home()
    assert not dev.run_window(0.5, from_first_contact=False).faults
    dev._x[K.Z2] = float("nan")  # not a number is beyond every bound too
    assert dev.run_window(0.5, from_first_contact=False).faults[0].code == "diverged"
