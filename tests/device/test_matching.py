"""Acceleration matching: identification, inversion, libraries, vibration fits."""

import os

import numpy as np
import pytest
from scipy import signal

from device import LibraryTransient, Material, Ringing, Scene, SceneError, Support, TransientTable
from device.matching.compare import scene_distances
from device.matching.inversion import (
    DiscreteModel,
    _stable_inverse,
    direct_inverse,
    discretize,
    invert,
)
from device.matching.library import (
    LibraryError,
    Tap,
    TransientLibrary,
    build_into_store,
    build_library,
    even_spread,
    find_library,
    library_dir,
    library_path,
    record_taps,
    segment_taps,
)
from device.matching.sysid import (
    ETFE,
    etfe,
    fit_transfer_function,
    identify_system,
    swept_sine,
    true_response,
)
from device.matching.vibration import fit_vibration
from device.sim.backend import SimDevice
from device.sim.plant import Y, build_plant
from protocols import load_protocol

RATE = 10_000.0


@pytest.fixture(scope="module")
def ident():
    return identify_system(SimDevice(seed=1))


@pytest.fixture(scope="module")
def realism():
    return load_protocol("realism")


def true_plant(dev):
    p = build_plant(dev.params, dev.hand)
    row = np.zeros(p.n_states + 3)
    row[Y] = 1.0
    return p, row


def test_swept_sine_design():
    sw = swept_sine(RATE, (10.0, 500.0), 2.5, amplitude=1.5, extend=1.5, silence=0.5)
    f = sw.force
    assert np.max(np.abs(f)) <= 1.5 + 1e-12
    assert np.all(f[-int(0.5 * RATE):] == 0)  # trailing silence
    assert abs(f[0]) < 1e-3 * 1.5  # faded in
    # the sweep spends 2.5 s inside the band: it starts below 10 Hz and ends above 500 Hz
    n_sweep = len(f) - int(0.5 * RATE)
    assert n_sweep / RATE > 2.5
    spec = np.abs(np.fft.rfft(f))
    freq = np.fft.rfftfreq(len(f), 1 / RATE)
    band = (freq > 15) & (freq < 450)
    pink = spec[band] * np.sqrt(freq[band])  # an exponential sweep's amplitude goes as 1/√f
    assert pink.min() > 0.8 * pink.max()
    with pytest.raises(ValueError, match="band must satisfy"):
        swept_sine(1000.0, (10.0, 500.0))


def test_etfe_recovers_a_known_filter_and_averaging_helps():
    b, a = signal.butter(2, 150, fs=RATE)
    sw = swept_sine(RATE)
    rng = np.random.default_rng(0)
    y = signal.lfilter(b, a, sw.force)
    ys = y + rng.normal(0, 0.05, (8, y.size))
    _, htrue = signal.freqz(b, a, worN=np.fft.rfftfreq(y.size, 1 / RATE), fs=RATE)
    one = etfe(sw.force, ys[:1], RATE)
    eight = etfe(sw.force, ys, RATE)
    band = (one.freq > 10) & (one.freq < 500)
    err1 = np.median(np.abs(one.H[band] / htrue[band] - 1))
    err8 = np.median(np.abs(eight.H[band] / htrue[band] - 1))
    assert err8 < err1 / 2  # noise falls about as 1/√8 ≈ 0.35
    assert err8 < 0.02
    assert np.all((eight.coherence >= 0) & (eight.coherence <= 1))
    passband = (eight.freq > 10) & (eight.freq < 150)
    stopband = (eight.freq > 400) & (eight.freq < 500)
    assert eight.coherence[passband].min() > 0.99
    assert eight.coherence[stopband].mean() < eight.coherence[passband].mean()  # SNR falls


def test_fit_is_exact_on_noise_free_plant_response():
    dev = SimDevice()
    p, row = true_plant(dev)
    f = np.linspace(1, 1000, 2000)
    est = ETFE(f, true_response(p.A[0], p.B[0], row, f), np.ones_like(f))
    m = fit_transfer_function(est, 7, 4, delay=0.0)
    assert m.order == 7 and m.relative_degree == 4
    assert m.err_db_max < 1e-6 and m.err_deg_max < 1e-6
    # the numerator is s²·(b_l·s + k_l): zeros at 0, 0 and −k_l/b_l = −5250 rad/s
    z = np.sort(np.abs(np.roots(np.trim_zeros(m.num, "f"))))
    assert z[:2] == pytest.approx([0, 0], abs=1e-2) and z[2] == pytest.approx(5250, rel=1e-6)
    with pytest.raises(ValueError, match="relative degree"):
        fit_transfer_function(est, 3, 5)


@pytest.mark.slow
def test_identified_model_matches_the_true_plant_not_just_the_estimate(ident):
    """Judged against the simulator's known plant (coherence alone does not certify it):
    within 1.5 dB and 3° over 10–500 Hz (measured: 1.0 dB, 0.4°)."""
    dev = SimDevice()
    p, row = true_plant(dev)
    e = ident.etfe.in_band((10, 500))
    ht = true_response(p.A[0], p.B[0], row, e.freq, RATE)  # with the ZOH of the command
    r = ident.model.response(e.freq) / ht
    assert np.max(np.abs(20 * np.log10(np.abs(r)))) < 1.5
    assert np.max(np.abs(np.degrees(np.angle(r)))) < 3.0
    assert e.freq[np.argmax(np.abs(e.H))] == pytest.approx(128, abs=4)  # the 130-Hz resonance


@pytest.mark.slow  # the plant identified from the simulated device (module fixture)
def test_discretization_matches_the_continuous_model_with_its_delay(ident):
    m = ident.model
    from dataclasses import replace

    for delay in (0.0, 0.25e-3, 0.33e-3):
        md = replace(m, delay=delay)
        dm = discretize(md, RATE)
        f = np.array([20.0, 60.0, 130.0, 300.0])
        T = 1 / RATE
        expected = md.response(f) * np.exp(-1j * np.pi * f * T) * np.sinc(f * T)
        np.testing.assert_allclose(dm.response(f), expected, rtol=0.01)


@pytest.mark.slow  # the plant identified from the simulated device (module fixture)
def test_sampled_rel_degree_4_has_unstable_zeros_and_the_direct_inverse_diverges(ident):
    from dataclasses import replace

    dm = discretize(replace(ident.model, delay=0.25e-3), RATE)
    assert np.any(np.abs(dm.zeros) > 1.0)
    t = np.arange(1000) / RATE
    target = 10 * np.exp(-18 * t) * np.sin(2 * np.pi * 66 * t)
    with np.errstate(all="ignore"):
        u = direct_inverse(dm, target)
    assert not np.all(np.isfinite(u[:100])) or np.nanmax(np.abs(u[:100])) > 1e6  # within 10 ms
    for method in ("regularized", "stable", "windowed"):
        inv = invert(dm, target, method)
        assert np.all(np.isfinite(inv.force)) and np.max(np.abs(inv.force)) < 5.0


def test_stable_inverse_is_exact_on_a_nonminimum_phase_system():
    b = np.convolve([0, 1], np.convolve([1, -0.5], [1, 3]))  # zeros at 0.5 and −3
    a = np.array([1, -0.9])
    dm = DiscreteModel(b, a, RATE)
    y = np.zeros(400)
    y[100:200] = np.sin(np.linspace(0, 6 * np.pi, 100))
    u = _stable_inverse(dm, y, 400, 10.0, 4000.0)
    np.testing.assert_allclose(signal.lfilter(b, a, u)[400:800], y, atol=1e-12)


@pytest.mark.slow  # the plant identified from the simulated device (module fixture)
@pytest.mark.parametrize("method", ["regularized", "stable"])
def test_inversion_through_the_forward_model(ident, method):
    """A 66-Hz decaying target: in-window error ≤ 0.35 (measured 0.30–0.31; half of it in
    the first 5 ms, which a relative-degree-4 device cannot follow), and ≤ 10 % of the
    force energy outside the window (measured 4 %)."""
    dm = discretize(ident.model, RATE)
    t = np.arange(1000) / RATE
    inv = invert(dm, 10 * np.exp(-18 * t) * np.sin(2 * np.pi * 66 * t), method)
    assert inv.in_window_error < 0.35
    assert inv.energy_outside < 0.10
    assert inv.force[0] == 0.0 and abs(inv.force[-1]) < 1e-9  # tapered
    with pytest.raises(ValueError, match="inversion method"):
        invert(dm, t, "magic")


def test_transient_table_blend_policies():
    v = np.array([0.05, 0.10, 0.20])
    f = np.stack([np.full(4, 1.0), np.full(4, 2.0), np.full(4, 4.0)])
    lin = TransientTable(v, f, "linear", 0.8)
    assert lin.force_at(0.15)[0] == pytest.approx(0.8 * 3.0)  # halfway between rows 2 and 3
    assert lin.force_at(0.025)[0] == pytest.approx(0.8 * 0.5)  # below: slowest × v/v0
    assert lin.force_at(0.40)[0] == pytest.approx(0.8 * 8.0)  # above: fastest × v/vmax
    near = TransientTable(v, f, "nearest")
    assert near.force_at(0.12)[0] == pytest.approx(2.0 * 0.12 / 0.10)
    with pytest.raises(Exception, match="ascending"):
        TransientTable([0.2, 0.1], np.ones((2, 3)))


def test_kernel_plays_the_blend_the_table_describes(tmp_path):
    """The compiled servo loop and TransientTable.force_at agree at every contact."""
    dev = SimDevice(seed=8)
    rng = np.random.default_rng(1)
    v = np.array([0.06, 0.09, 0.12, 0.15])
    forces = rng.normal(0, 0.5, (4, 300))
    lib = TransientLibrary(v, forces, {"format_version": 1, "servo_rate_hz": RATE,
                                       "device": {**dev.info.to_dict(), "servo_rate_hz": RATE}})
    path = lib.save(tmp_path / "lib.npz")
    scene = Scene("m", spring=680.0, transient=LibraryTransient("x", 0.8, "linear", str(path)))
    dev.load_scene(scene)
    dev.home()
    res = dev.run_window(2.0)
    tr = res.traces
    table = lib.table(0.8, "linear")
    assert len(res.contacts) >= 2
    for c in res.contacts:
        i = int(round((c.t - tr["t"][0]) * RATE))
        n = min(300, len(tr["t"]) - i)
        spring = 680.0 * np.maximum(-tr["position"][i:i + n], 0.0)
        np.testing.assert_allclose(tr["force_cmd"][i:i + n] - spring,
                                   table.force_at(c.velocity)[:n], atol=1e-9)


def test_library_file_round_trip_and_refusals(tmp_path):
    dev = SimDevice()
    meta = {"format_version": 1, "servo_rate_hz": RATE,
            "device": {**dev.info.to_dict(), "servo_rate_hz": RATE}}
    lib = TransientLibrary(np.array([0.05, 0.1]), np.arange(20.0).reshape(2, 10), meta)
    path = lib.save(tmp_path / "a.npz")
    back = TransientLibrary.load(path, dev.info)
    assert back.sha256 == lib.sha256
    np.testing.assert_array_equal(back.forces, lib.forces)
    # another device (other servo rate → other configuration) is refused
    with pytest.raises(LibraryError, match="made on .* but this is"):
        TransientLibrary.load(path, SimDevice(rate_hz=1000).info)
    # a corrupt byte in the data
    raw = bytearray(path.read_bytes())
    k = raw.find(np.float64(13.0).tobytes())
    raw[k] ^= 0x01
    bad = tmp_path / "bad.npz"
    bad.write_bytes(bytes(raw))
    with pytest.raises(LibraryError, match="content hash mismatch|corrupt"):
        TransientLibrary.load(bad)
    # truncated file, unknown version, missing file
    (tmp_path / "cut.npz").write_bytes(bytes(raw[:100]))
    with pytest.raises(LibraryError, match="corrupt, or not a transient library"):
        TransientLibrary.load(tmp_path / "cut.npz")
    v2 = TransientLibrary(lib.velocities, lib.forces, {**meta, "format_version": 99})
    with pytest.raises(LibraryError, match="version 99"):
        TransientLibrary.load(v2.save(tmp_path / "v2.npz"))
    with pytest.raises(LibraryError, match="no such library file"):
        TransientLibrary.load(tmp_path / "nothing.npz")


def test_even_spread_and_segmentation(realism):
    v = np.array([0.05, 0.051, 0.08, 0.11, 0.112, 0.14, 0.2])
    pick = even_spread(v, 4)
    assert len(pick) == 4 and v[pick[0]] == 0.05 and v[pick[-1]] == 0.2
    assert np.all(np.diff(v[pick]) > 0)
    results = record_taps(SimDevice(seed=4), realism.samples["wood_on_foam"].scene, 2)
    taps = segment_taps(results)
    assert len(taps) >= 8
    assert all(len(t.accel) == 1000 and t.velocity > 0 for t in taps)
    # a record lost on the link (NaN, as the serial backend fills a gap) inside one tap's
    # window drops that tap only
    first = taps[0]
    res = next(r for r in results if r.traces["t"][0] <= first.t <= r.traces["t"][-1])
    i = int(round((first.t - res.traces["t"][0]) * res.rate_hz)) + 500
    res.traces["accel"][i] = np.nan
    gapped = segment_taps(results)
    assert len(gapped) == len(taps) - 1 and first.t not in {t.t for t in gapped}


@pytest.mark.slow
def test_a_library_is_built_explicitly_into_the_store_and_found_there(realism):
    scene = realism.samples["matched_firm"].scene
    source = realism.samples["wood_on_foam"].scene
    dev = SimDevice(seed=5)
    if find_library(dev.info, scene.transient) is None:
        # loading a matched scene never runs an experiment: without a library it is refused,
        # naming the command that builds one
        with pytest.raises(SceneError, match="library build --device SPEC --source "
                                             "wood_on_foam"):
            dev.load_scene(scene)
        build_into_store(SimDevice(seed=20_260_001), source)
    path = find_library(dev.info, scene.transient)
    assert path == library_path(dev.info, source) and path.is_relative_to(library_dir())
    mtime = path.stat().st_mtime_ns
    dev.load_scene(scene)
    SimDevice(seed=6).load_scene(realism.samples["matched_soft"].scene)
    assert path.stat().st_mtime_ns == mtime  # found, not rebuilt
    lib = TransientLibrary.load(path, dev.info)
    assert lib.provenance["source"]["sample"] == "wood_on_foam"
    assert 8 <= len(lib.velocities) <= 12
    # peak force grows with the incoming speed (momentum), roughly linearly
    peaks = np.abs(lib.forces).max(axis=1)
    assert np.corrcoef(lib.velocities, peaks)[0, 1] > 0.8
    # another simulated configuration (another servo rate) is another device: not found
    assert find_library(SimDevice(rate_hz=1000).info, scene.transient) is None
    # a library transient with neither a path nor its source scene (not loaded through a
    # protocol) has nothing to look up
    assert find_library(dev.info, LibraryTransient("wood_on_foam")) is None


def test_build_library_refuses_virtual_sources():
    with pytest.raises(ValueError, match="real sample"):
        build_library(SimDevice(), Scene("v", spring=100.0))


@pytest.mark.slow  # builds the realism library when no test before it has
def test_matched_scenes_are_closer_to_wood_on_foam_than_pulse_or_sinusoid(realism):
    """Spectral distance (device.matching.compare, 10–500 Hz) to taps on the real
    wood_on_foam, a 6-g balsa plate on foam (issue 14's block model).

    Measured (seeds 11–13, 4 windows): matched 2.2–2.7 dB; pulse 4.4–4.8; sinusoid
    4.6–4.9. (The old tuned ringing gave matched 1.8–2.0, pulse 6.3, sinusoid 6.5.) The
    springs (0.8–1.1) and foam (0.6) are closer still: a 6-g plate sinks into the foam with
    the stylus, so the low band, where they agree, dominates this distance."""
    names = ("matched_firm", "matched_soft", "pulse_firm", "pulse_soft", "sinusoid_firm",
             "sinusoid_soft")
    source = realism.samples["wood_on_foam"].scene
    if find_library(SimDevice(seed=11).info, realism.samples["matched_firm"].scene.transient) \
            is None:
        build_into_store(SimDevice(seed=20_260_001), source)
    d = scene_distances(lambda: SimDevice(seed=11), {n: realism.samples[n].scene for n in names},
                        source, windows=4)
    worst_matched = max(d["matched_firm"], d["matched_soft"])
    assert worst_matched < min(d[n] for n in names[2:]) - 1.5


@pytest.mark.parametrize("A, B, f", [(-1500, 600, 592), (-800, 150, 300), (-300, 90, 250),
                                     (-100, 18.2, 66), (-116.7, 40, 18), (-240, 60, 30)])
def test_vibration_fit_recovers_known_models(A, B, f):
    """Taps that are the model: Q through the accelerometer (2nd-order 1 kHz) plus 0.3 m/s²
    noise, speeds N(0.11, 0.033). Tolerances: f within 1.5 %, B and A within 7 %
    (measured: ≤ 1.2 %, ≤ 4.8 %, ≤ 5.3 %)."""
    rng = np.random.default_rng(0)
    sos = signal.butter(2, 1000, fs=RATE, output="sos")
    t = np.arange(1000) / RATE
    ring = Ringing(A, B, f)
    taps = [Tap(v, signal.sosfilt(sos, ring.acceleration(t, v)) + rng.normal(0, 0.3, t.size), 0.0)
            for v in np.clip(rng.normal(0.11, 0.033, 40), 0.03, 0.3)]
    fit = fit_vibration(taps, RATE, band=(0.5 * f, 2 * f), accel_bandwidth=1000)
    assert fit.frequency == pytest.approx(f, rel=0.015)
    assert fit.decay == pytest.approx(B, rel=0.07)
    assert fit.slope == pytest.approx(A, rel=0.07)


def test_vibration_fit_on_device_taps_of_real_wood():
    """Taps simulated through the device on the factorial's wood block (26 g on a contact
    and support derived from Table 1's ringing, issue 14). At the tapper's default speeds
    (up to ~0.2 m/s) the fitted f is within 10 % of 592 Hz and B within 30 % of 600 1/s
    (measured seeds 2, 3: f 623, 557; B 662, 762): above ~0.1 m/s the ringing force
    exceeds the hand's preload and the stylus chatters, which shortens the ring-down.
    A reads −664…−673 1/s, under half of Table 1's −1500: a passive 26-g block cannot
    ring harder than the contact excites it (tests/device/test_passive_samples.py checks
    the slow-tap fit within 10 %)."""
    wood = Scene("wood", material=Material(70_000.0, ringing=Ringing(-1500.0, 600.0, 592.0),
                                           mass=0.026))
    taps = segment_taps(record_taps(SimDevice(seed=2), wood, 6))
    fit = fit_vibration(taps, RATE, band=(296, 1184), accel_bandwidth=1000)
    assert fit.frequency == pytest.approx(592, rel=0.10)
    assert fit.decay == pytest.approx(600, rel=0.30)
    assert -1500 < fit.slope < -300


def test_the_simulated_rubber_block_gives_the_measured_rubber_model():
    """Rubber's measured 18 Hz (Table 1: A = −116.7, B = 40, f = 18) is the hand and stylus
    bouncing on the rubber, so the factorial protocol's rubber block is that contact alone.
    Across seeds 2–4 its taps fit f 17.8–22.9 Hz, B 34–56 1/s, A −80…−118 1/s; a stiff
    contact with the measured ringing added on top (the protocol's earlier block) fits about
    28 Hz and −207 1/s (before issue 14; a ringing now needs a block mass)."""
    from protocols import load_protocol

    def fit(scene):
        taps = segment_taps(record_taps(SimDevice(seed=2), scene, 6))
        return fit_vibration(taps, RATE, band=(9, 72), accel_bandwidth=1000)

    block = fit(load_protocol("factorial").samples["rubber-real"].scene)
    assert 15 < block.frequency < 25 and 25 < block.decay < 60 and -150 < block.slope < -70


def test_library_dir_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("HAPTICLAB_LIBRARIES", str(tmp_path))
    assert library_dir() == tmp_path
    assert os.environ["HAPTICLAB_LIBRARIES"] == str(tmp_path)


def test_identification_refuses_a_device_that_thins_its_accelerometer_out():
    """A device whose link can carry the accelerometer only every 4th tick is refused in
    words before anything is played (the ETFE divides spectra tick by tick), and its
    channels are given back."""
    from types import SimpleNamespace

    from device import DeviceError, open_device
    from device.matching.sysid import identify_system

    with open_device("sim") as sim:
        info = sim.info
    asked = []

    def set_trace_channels(channels=None):
        asked.append(channels)
        return info.servo_rate_hz / 4

    def play_force(force):
        raise AssertionError("nothing may be played")

    narrow = SimpleNamespace(info=info, set_trace_channels=set_trace_channels,
                             play_force=play_force)
    with pytest.raises(DeviceError, match="carries the accelerometer at 2500 Hz, not at every "
                                          "servo tick \\(10000 Hz\\)"):
        identify_system(narrow)
    assert asked == [("accel",), None]


def test_the_verdict_weighs_the_library_against_its_spring_alone():
    """The README's own example was called 'fair' at 3.0 dB while the spring alone scored
    2.3 dB: a verdict that ignored its baseline. It says when the library gains nothing."""
    from device.matching.compare import Verification

    fair = Verification(3.04, 2.3, 16, 15).verdict()  # printed as 3.0
    assert fair.startswith("fair") and "no closer than the spring alone (2.3 dB)" in fair
    better = Verification(2.0, 4.5, 16, 15).verdict()
    assert better.startswith("close") and "spring alone" not in better
    assert Verification(7.0, 9.0, 10, 10).verdict().startswith("far")


def test_a_vibration_fit_that_finds_no_ring_down_says_what_it_found():
    """Silent taps (an accelerometer that is not connected) or taps with no incoming speed:
    the error counts the taps kept, names the band and why taps were left out, instead of
    "the taps hold no decaying vibration" alone."""
    silent = np.zeros(1000)
    taps = [Tap(0.1, silent, 0.0), Tap(0.1, silent.copy(), 1.0), Tap(0.0, silent, 2.0)]
    with pytest.raises(ValueError) as err:
        fit_vibration(taps, 10_000, band=(300, 1200))
    msg = str(err.value)
    assert msg.startswith("0 of 3 taps hold a vibration that decays") and "300–1200 Hz" in msg
    assert "1 without an incoming speed" in msg and "a slope needs 2" in msg


def test_the_store_refuses_a_library_matched_over_another_band(tmp_path, monkeypatch):
    """A library matched over 10–1000 Hz would take the protocol's library's place in the
    store (its path does not name the band): refused before anything is measured; its own
    build record is kept apart by its key."""
    from device.matching.library import PAPER_BAND, build_key

    monkeypatch.setenv("HAPTICLAB_LIBRARIES", str(tmp_path))
    src = Scene("wood_on_foam", material=Material(70_000.0, 20.0, mass=0.006,
                                                  support=Support(350.0, 3.0)))
    dev = SimDevice()
    with pytest.raises(ValueError, match=r"save one matched over \(10.0, 1000.0\) Hz under"):
        build_into_store(dev, src, band=(10.0, 1000.0))
    assert not list(tmp_path.iterdir())
    assert build_key(dev.info, src)["band"] == list(PAPER_BAND)
    assert build_key(dev.info, src, band=(10.0, 1000.0)) != build_key(dev.info, src)


@pytest.mark.slow  # the plant identified from the simulated device (module fixture)
def test_a_library_played_over_a_spring_can_leave_the_springs_share_out(ident, realism):
    """``build_library(under=spring)``: each target is the tap less the spring's
    least-squares response per unit speed times the tap's speed, recomputed here from the
    same device's taps (the source's windows, then the spring's: the order the build taps
    them in). The inversion is linear in its target, so each transient is the whole tap's
    less the speed times the inverse of that response. A real ``under``, one with a
    transient and the store are refused."""
    from dataclasses import replace

    from device.matching.inversion import discretize, invert
    from device.matching.library import TAP_SECONDS, even_spread, record_taps

    source = realism.samples["wood_on_foam"].scene
    spring = replace(realism.samples["matched_firm"].scene, transient=None)
    lib = build_library(SimDevice(seed=8), source, entries=4, windows=2, model=ident.model,
                        under=spring)
    assert lib.provenance["superposed_on"]["taps"] >= 2
    assert lib.provenance["superposed_on"]["scene"]["spring"] == spring.spring
    dev = SimDevice(seed=8)
    taps = segment_taps(record_taps(dev, source, 2, TAP_SECONDS))
    own = segment_taps(record_taps(dev, spring, 2, TAP_SECONDS))
    per_speed = sum(t.velocity * t.accel for t in own) / sum(t.velocity ** 2 for t in own)
    dm = discretize(ident.model, dev.info.servo_rate_hz)
    pick = even_spread(np.array([t.velocity for t in taps]), 4)
    for row, i in zip(lib.forces, pick, strict=True):
        whole = invert(dm, taps[i].accel).force
        share = invert(dm, per_speed).force
        want = whole - taps[i].velocity * share
        assert np.max(np.abs(row - want)) <= 1e-9 * np.max(np.abs(whole))
        # the spring's share is a real part of the transient, not a rounding
        assert np.max(np.abs(row - whole)) > 0.05 * np.max(np.abs(whole))
    with pytest.raises(ValueError, match="over a spring alone; 'wood_on_foam' is real"):
        build_library(SimDevice(), source, model=ident.model, windows=2, under=source)
    matched = realism.samples["matched_firm"].scene
    with pytest.raises(ValueError, match="is a spring with a transient"):
        build_library(SimDevice(), source, model=ident.model, windows=2, under=matched)
    with pytest.raises(ValueError, match="libraries of whole taps"):
        build_into_store(SimDevice(), source, under=spring)
