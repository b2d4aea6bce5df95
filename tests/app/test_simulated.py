"""Simulated participants: ratings follow what is felt, studies are reproducible, and the
papers' main findings emerge (or are listed in the issue note where they do not)."""

import json
import math
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from analysis import load_sessions
from analysis.analyses import analyse_recorded
from app.participant_model import SimulatedParticipant, felt_features
from device import open_device
from protocols import load_protocol

CLI = [sys.executable, "-m", "app"]


def _window(scene, seed=5):
    with open_device("sim", seed=seed) as dev:
        dev.load_scene(scene)
        dev.home()
        return dev.run_window(5.0)


def test_features_follow_the_rendering_not_the_name():
    p = load_protocol("realism")
    wood, spring = p.samples["wood"].scene, p.samples["firm_spring"].scene
    f_wood, f_spring = felt_features(_window(wood)), felt_features(_window(spring))
    assert np.all(np.isfinite(f_wood)) and np.all(np.isfinite(f_spring))
    # wood stops the stylus sooner (log stop time) with a bigger jolt and a higher pitch
    assert f_wood[0] < f_spring[0] - 1 and f_wood[1] > f_spring[1] + 1
    assert f_wood[2] > f_spring[2]
    # the same rendering under another name feels the same
    renamed = replace(spring, name="wood")
    assert felt_features(_window(renamed)) == pytest.approx(f_spring)


def test_each_person_holds_and_taps_the_stylus_their_own_way():
    from device.sim.params import HandParams
    from device.sim.tapper import Tapper

    p = load_protocol("realism")
    people = [SimulatedParticipant(p, seed=s) for s in (1, 2)]
    held = []
    with open_device("sim", seed=0) as dev:  # the simulated device: its hand is public state
        dev.load_scene(p.samples["wood"].scene)
        for person in people:
            person.before_window(None, "wood", dev, None)
            held.append((dev.hand, dev.tapper))
        assert dev.nominal_hand == HandParams()
    for person, (hand, tapper) in zip(people, held, strict=True):
        g, r = person.person.grasp, person.person.rhythm
        assert hand.stiffness == pytest.approx(300.0 * g) and hand.damping == pytest.approx(4 * g)
        assert tapper.pause == pytest.approx(tuple(x * r for x in Tapper().pause))
        assert tapper.velocity_mean == person.person.tap_speed
    assert held[0][0] != held[1][0] and held[0][1].pause != held[1][1].pause


def test_a_changed_rendering_changes_the_rating():
    p = load_protocol("realism")
    person = SimulatedParticipant(p, seed=3)
    ref = felt_features(_window(p.samples["wood"].scene, seed=1))
    person.memory["reference"] = ref
    near = [person.distance(felt_features(_window(p.samples["wood"].scene, seed=s)), ref,
                            np.random.default_rng(s)) for s in range(3)]
    far = [person.distance(felt_features(_window(p.samples["soft_spring"].scene, seed=s)),
                           ref, np.random.default_rng(s)) for s in range(3)]
    assert max(near) + 3 < min(far)  # JND units
    # on the scale (range principle): the first sample felt lands mid-scale; then the
    # nearest so far is at the top, the farthest at the bottom
    # (hi - d) / (hi - lo) with lo, hi = d ∓ prior/2 rounds to 0.5 within a few ulps of d
    assert person.position("reference", far[0]) == pytest.approx(0.5, abs=1e-12)
    assert person.position("reference", near[0]) == 1.0
    assert person.position("reference", far[1]) < 0.1
    assert person.position("reference", near[1]) > 0.8


@pytest.mark.slow
def test_experts_identify_more_reliably_than_novices():
    """Same surfaces felt, same remembered blocks: only the perceptual noise differs by group
    (app.participant_model.FEATURE_NOISE), so experts name the materials right more often (the
    paper's Table 3: 88.9 % against 79.2 %)."""
    from types import SimpleNamespace

    p = load_protocol("identification")
    order = ("wood", "aluminum", "rubber")
    windows = [[_window(p.samples[s].scene, seed=10 * k + i) for i, s in enumerate(order)]
               for k in range(3)]
    trial = SimpleNamespace(samples=order)
    score = {}
    with open_device("sim", seed=0) as dev:
        for group in ("expert", "novice"):
            hits = 0
            for person in range(40):
                sp = SimulatedParticipant(p, seed=person, group=group)
                sp._device = dev
                for k, res in enumerate(windows):
                    answer, _ = sp.identify(trial, p.answer.choices, res,
                                            np.random.default_rng([person, k]))
                    hits += list(answer) == list(order)
            score[group] = hits / 120
    assert score["expert"] > score["novice"] + 0.05, score
    assert score["novice"] > 0.5, score  # chance is 1/6


@pytest.mark.slow
def test_identification_improves_with_practice():
    """Same surfaces felt, only the repetition differs: perception noise shrinks by
    ID_LEARNING per repetition done, so the third attempt is named right more often than the
    first (the paper: 35 of 42 overall, 12 of 14 on the third)."""
    from types import SimpleNamespace

    p = load_protocol("identification")
    order = ("wood", "rubber", "aluminum")
    windows = [_window(p.samples[s].scene, seed=40 + i) for i, s in enumerate(order)]
    score = {1: 0, 3: 0}
    with open_device("sim", seed=0) as dev:
        for person in range(60):
            for rep in score:
                sp = SimulatedParticipant(p, seed=person, group="novice")
                sp._device = dev
                trial = SimpleNamespace(samples=order, repetition=rep)
                answer, _ = sp.identify(trial, p.answer.choices, windows,
                                        np.random.default_rng([person, 99]))
                score[rep] += list(answer) == list(order)
    assert score[3] > score[1], score


@pytest.mark.parametrize("f, decay", [(18.0, 40.0), (30.0, 60.0), (100.0, 80.0),
                                      (300.0, 90.0), (592.0, 600.0)])
def test_pitch_window_adapts_to_slow_vibrations(f, decay):
    """A decaying sinusoid alone (10 kHz): the strongest vibration is found within 15 %
    (measured 15.8 Hz for 18 Hz: 150 ms hold 2.7 periods) and
    the onset window spans 1.5 of its periods (≥ 30 ms), so the pitch (a log-axis centroid,
    which reads a windowed sinusoid up to ~20 % low at every frequency alike) is within
    25 % of f — at 18 Hz too, where a fixed 30-ms window read ~63 Hz.
    Measured: 18 → 19.5 Hz, 30 → 28.2, 100 → 80.0, 300 → 265, 592 → 473."""
    from app.participant_model import (
        ONSET_MAX_S,
        ONSET_MIN_S,
        ONSET_PERIODS,
        _dominant_hz,
        _pitch_ring,
    )

    rate = 10_000.0
    t = np.arange(3000) / rate
    a = np.exp(-decay * t) * np.sin(2 * np.pi * f * t)
    f0 = _dominant_hz(a[:int(ONSET_MAX_S * rate)], rate)
    assert f0 == pytest.approx(f, rel=0.15)
    m = int(np.clip(ONSET_PERIODS / f0, ONSET_MIN_S, ONSET_MAX_S) * rate)
    pitch, ring = _pitch_ring(a, m, rate)
    assert np.exp(pitch) == pytest.approx(f, rel=0.25)
    assert ring > 0  # it dies out


@pytest.fixture(scope="module")
def study_dir(demo_study):
    """The demo's sessions (realism 9, factorial 9, identification 6 experts and 8
    novices), shared with every test that reads a whole simulated study."""
    assert demo_study.returncode == 0, demo_study.stderr
    return demo_study.out / "data"


@pytest.fixture(scope="module")
def study(study_dir):
    return load_sessions(study_dir)


@pytest.fixture(scope="module")
def factorial_study(tmp_path_factory):
    """The factorial study of seed 1, of which test_face_validity_factorial's docstring
    says what emerges (the demo's seeds differ)."""
    data = tmp_path_factory.mktemp("factorial")
    out = subprocess.run([*CLI, "simulate", "factorial", "--participants", "9", "--seed", "1",
                          "--data", str(data), "--prefix", "F", "--traces", "none"],
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr
    return load_sessions(data)


def realism(study):
    return analyse_recorded(study, "realism", "testing")["result"]


@pytest.mark.integration
@pytest.mark.slow
def test_face_validity_realism(study):
    r = realism(study)
    means = {s["sample"]: s["mean"] for s in r["samples"]}
    # wood (the real sample felt during familiarization) is rated highest
    assert max(means, key=means.get) == "wood"
    # the springs and foam lie below the transient renderings on average
    low = np.mean([means[s] for s in ("firm_spring", "soft_spring", "foam")])
    mid = np.mean([means[s] for s in ("pulse_firm", "pulse_soft", "sinusoid_firm",
                                      "sinusoid_soft", "matched_firm", "matched_soft")])
    assert low < mid
    # matched renderings are not distinguishable from the sample they were matched to, and
    # firm_spring not from foam (Holm-adjusted p >= .05)
    pw = r["pairwise"].set_index(["A", "B"])

    def p_holm(a, b):
        return float(pw.loc[(a, b), "p_holm"] if (a, b) in pw.index else pw.loc[(b, a), "p_holm"])

    for a, b in (("matched_firm", "wood_on_foam"), ("matched_soft", "wood_on_foam"),
                 ("firm_spring", "foam")):
        assert p_holm(a, b) >= 0.05, (a, b)


@pytest.mark.integration
def test_face_validity_taps_and_saturations(study):
    dev = analyse_recorded(study, "realism", "testing")["device"]
    assert 0.09 < dev["velocity_mean"] < 0.13 and 0.02 < dev["velocity_sd"] < 0.05
    sat = dev["saturations_per_sample"]
    heavy = sum(v for k, v in sat.items() if k.startswith(("sinusoid", "matched")))
    assert heavy >= 0.8 * sum(sat.values()) and heavy > 0


@pytest.mark.integration
def test_face_validity_identification(study):
    i = analyse_recorded(study, "identification", "identification")["result"]
    t = {row["scope"]: row for row in i["table"].to_dict(orient="records")}
    assert t["all"]["percent"] > 60 and t["all"]["p_binom"] < 1e-6


@pytest.mark.integration
def test_face_validity_factorial(factorial_study):
    """What emerges in every seed tried (1, 2, 3; p values below are the range over them):
    for wood, frequency (p ≤ .006) and slope (p ≤ .048) matter and their high levels,
    toward the measured 592-Hz, −1500-1/s model, are preferred — frequency matters most in
    two seeds of three, as in the paper; for aluminum, the higher slope (toward the measured
    model's far larger amplitude) is preferred (p ≤ .004). What does not emerge (aluminum's
    300 Hz, rubber's direction) is explained in the README: mostly the simulated device."""
    res = analyse_recorded(factorial_study, "factorial", "rating")["result"]
    for mat, factors in (("wood", ("frequency", "slope")), ("aluminum", ("slope",))):
        effects = res[mat]["main_effects"].set_index("factor")
        for factor in factors:
            assert effects.loc[factor, "preferred"] == "high", (mat, factor)
            assert effects.loc[factor, "p_unc"] < 0.05, (mat, factor)
    assert res["wood"]["most_significant"] in ("frequency", "slope")
    # the range principle: no material's sets all sit on the floor or the ceiling
    for mat in ("rubber", "wood", "aluminum"):
        assert res[mat]["preflight"].empty, mat


@pytest.mark.integration
def test_power_from_a_factorial_pilot_says_what_it_cannot_estimate(study_dir):
    """A factorial pilot rates each set once: the trial SD cannot be told from the
    participant × set SD. It used to print NaN (invalid JSON); now it says so, and with
    --sd-trial it computes, every number finite."""
    import json

    out = subprocess.run([*CLI, "power", "factorial", "--pilot", str(study_dir), "--subjects",
                          "9", "--reps", "1", "--experiments", "200", "--json"],
                         capture_output=True, text=True)
    assert out.returncode == 2 and "--sd-trial" in out.stderr and not out.stdout
    out = subprocess.run([*CLI, "power", "factorial", "--pilot", str(study_dir), "--subjects",
                          "9", "--reps", "1", "--experiments", "200", "--sd-trial", "0.8",
                          "--json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert got["sd_trial"] == 0.8 and got["sd_interaction"] >= 0


@pytest.mark.integration
def test_familiarization_windows_are_tapped_afresh(study_dir):
    """The two familiarization windows each get their own seed: no run of four tap speeds
    repeats within a participant's familiarization (it did, exactly, when both windows were
    reseeded alike), and no two participants tap alike."""
    import csv

    seen = []
    for f in sorted(study_dir.glob("sub-R*/ses-*/trials.tsv")):
        with f.open(newline="") as fh:
            row = next(r for r in csv.DictReader(fh, delimiter="\t")
                       if r["phase"] == "familiarization")
        v = row["tap_velocities"].split(";")
        assert len(v) >= 8, f
        runs = [tuple(v[i:i + 4]) for i in range(len(v) - 3)]
        assert len(set(runs)) == len(runs), f
        seen.append(tuple(v))
    assert len(seen) == 9 and len(set(seen)) == 9


@pytest.mark.integration
@pytest.mark.slow
def test_session_length_from_a_simulated_study(study_dir, study):
    """`power --pilot` takes the SDs from the analysed (testing) phase of simulated
    sessions, and the precision it predicts for the study's own size (9 participants, 3
    repetitions) is close to the precision the study has: the median 95 % CI half-width of
    the 11 sample means, computed directly (t quantile × SD of participant means / √n).
    Measured: 0.434 predicted, 0.414 observed; the demo study's 0.37 against 0.44 shows the
    model's limit (one variance for every sample), hence 25 %."""
    import json

    from analysis.power import variance_components

    out = subprocess.run([*CLI, "power", "realism", "--pilot", str(study_dir), "--subjects",
                          "9", "--reps", "3", "--json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    testing = study[(study.protocol == "realism") & (study.phase == "testing") & study.valid]
    vc = variance_components(testing)
    assert got["sd_trial"] == pytest.approx(vc["sd_trial"])
    assert got["sd_subject"] == pytest.approx(vc["sd_subject"])
    predicted = got["rows"][0]["ci_halfwidth"]
    observed = np.median([s["ci_high"] - s["mean"] for s in realism(study)["samples"]])
    assert predicted == pytest.approx(observed, rel=0.25), (predicted, observed)


@pytest.mark.slow  # identifies the simulated device's plant
def test_aluminum_300_hz_is_beyond_the_simulated_device():
    """Why aluminum's 300-Hz sets lose to its 200-Hz ones (README): above the device's
    ~130-Hz resonance the same commanded model is felt with well under half the jolt, and
    both ring at the device's own frequency; compensating the response (the regularized
    inverse of the identified model, as for the matched library) would need more than 3×
    the force the current limit allows (3.0 N) at the mean tap speed."""
    from device.matching.inversion import discretize, invert
    from device.matching.sysid import identify_system
    from device.scene import Ringing
    from device.sim.backend import SimDevice

    p = load_protocol("factorial")
    low, high = (felt_features(_window(p.samples[s].scene)) for s in ("aluminum-LLL",
                                                                      "aluminum-HLL"))
    assert math.exp(high[1] - low[1]) < 0.5  # jolt ratio, 300 Hz against 200 Hz
    # the felt pitch moves by under half the model's pitch JND (0.5 log units), and down,
    # not up: both ring at the device's ~133 Hz (measured 0.185 log units with the adaptive
    # pitch window)
    from app.participant_model import JND

    assert abs(high[2] - low[2]) < JND[2] / 2 and high[2] < low[2]

    dev = SimDevice(seed=20_260_001)
    rate = dev.info.servo_rate_hz
    dm = discretize(identify_system(dev).model, rate)
    t = np.arange(int(0.1 * rate)) / rate
    target = Ringing(-200.0, 60.0, 300.0).acceleration(t, 1.0)  # aluminum-HLL, per m/s
    force = np.abs(invert(dm, target, "regularized").force).max() * 0.11  # N at 0.11 m/s
    limit = dev.params.force_constant * dev.params.current_limit
    assert force > 3 * limit, (force, limit)  # measured 12 N (the best set, A = −300: 17 N)


@pytest.mark.integration
@pytest.mark.slow
def test_simulate_is_reproducible(tmp_path):
    def run(d):
        out = subprocess.run([*CLI, "simulate", "identification", "--participants", "2",
                              "--seed", "4", "--data", str(d), "--traces", "none"],
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        cols = ["participant", "item", "attempt", "status", "answer", "correct", "n_taps"]
        return load_sessions(d)[cols].sort_values(["participant", "item", "attempt"])

    a, b = run(tmp_path / "a"), run(tmp_path / "b")
    assert a.reset_index(drop=True).equals(b.reset_index(drop=True))
    bad = subprocess.run([*CLI, "simulate", "realism", "--participants", "0"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "--participants" in bad.stderr


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_simulate_over_the_serial_link_to_the_emulator(tmp_path):
    """The whole path of a real session: pyserial over a pty to the device emulator (×10
    real time; the emulator backend starts one per session, seeded with the session's
    seed), the participant feeling the traces the link uploads. This is the run that found
    the emulator crashing on aluminum's ringing (a rebound read at 3.7 m/s did not fit the
    wire's contact field)."""
    out = subprocess.run([*CLI, "simulate", "factorial", "--participants", "1", "--seed", "2",
                          "--device", "emulator", "--speed", "10", "--data",
                          str(tmp_path), "--traces", "none"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    d = load_sessions(tmp_path)
    assert (d["status"] == "valid").sum() == 24 and set(d["device_backend"]) == {"emulator"}
    assert (d["status"] == "reference").sum() == 3  # each material's real block, tapped once
    meta = json.loads(next(tmp_path.rglob("session.json")).read_text())
    # what the device said over the wire (LIMITS), recorded: simulated, seeded, at ×10
    assert meta["device"]["firmware"] == "emulator-2x10" and meta["device"]["simulated_contact"]
    assert meta["device"]["seeded"] and not meta["device"]["virtual_time"]
    assert not meta.get("interruptions") and not meta.get("warnings")
    rated = d[d["status"] == "valid"]
    assert rated["rating"].between(1, 10).all() and rated["rating"].nunique() > 2
    bad = subprocess.run([*CLI, "simulate", "factorial", "--speed", "0"], capture_output=True,
                         text=True)
    assert bad.returncode == 2 and "--speed" in bad.stderr


@pytest.mark.integration
@pytest.mark.slow
def test_demo_writes_the_whole_study_and_its_report(demo_study):
    """`make demo`'s job (the run's one demo, shared with the face-validity tests)."""
    assert demo_study.returncode == 0, demo_study.stderr
    report = demo_study.out / "report"
    rep = json.loads((report / "report.json").read_text())
    assert (report / "report.html").stat().st_size > 10_000
    assert rep["methods"].startswith("These data come from simulated participants")
    assert rep["provenance"]["sessions"] == 9 + 9 + 14
    assert [a["id"] for a in rep["analyses"]] == [
        "factorial/rating", "identification/identification", "realism/testing"]
    assert "report.html" in demo_study.stdout and "simulating realism" in demo_study.stderr
