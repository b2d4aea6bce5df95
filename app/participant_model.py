"""A simulated participant who rates what the simulated hand feels.

This is a rehearsal tool, not a claim about people. It exists so that a whole study —
sessions, files, statistics, report — can be run and checked before anyone is recruited,
and so that a change in a rendering changes the ratings it gets.

Model
-----
**Tapping.** Each person has their own intended tap speed, drawn once from the population
N(0.11, 0.02²) m/s (SPEC §1 reports 0.11 ± 0.033 m/s over all taps) with a within-person
SD of 0.025 m/s; their own grasp, a factor exp(N(0, 0.2²)) (clipped to ±0.5 in the
exponent) on the hand's stiffness and damping (a firmer grip is stiffer and more damped;
the study asked for a consistent grasp, so the spread is modest); and their own rhythm, a
factor U(0.6, 1.6) on the dwell and pause between taps. The simulated device's hand taps
with them (:meth:`device.HapticDevice.set_simulated_hand`; over the serial link the
emulator's hand keeps the defaults).

**What is felt** (:func:`felt_features`), per contact, from the device's own traces (the
acceleration high-passed at ``HIGHPASS_HZ`` = 10 Hz: below that the hand feels a push, not
a vibration) and then the median over the window's taps (the first contact of each
stroke):

``stop``   log of the time from contact until the stylus stops [s] (how abruptly it stops);
``jolt``   log of the peak |acceleration| in the first 60 ms per incoming speed [1/s];
``pitch``  the spectral centroid of the acceleration's onset on a log-frequency axis,
           10–1500 Hz [log Hz]; the onset window is 1.5 periods of the contact's strongest
           vibration (found in the first 150 ms), at least 30 ms and at most 150 ms, weighted
           by exp(−3t / window): 30 ms and exp(−t / 10 ms) for anything above 50 Hz, while an
           18-Hz ringing is heard over 83 ms (a fixed 30 ms read rubber's 18 Hz as ~63 Hz);
``ring``   log of the ratio of the RMS acceleration in the first half of the onset window
           to that in the next full window (0–15 / 15–45 ms above 50 Hz): how quickly the
           vibration dies out.

Nothing here reads a sample's name: rename a sample and the ratings stay; change its
rendering and they change.

**Judging.** Each feature is perceived with Gaussian noise (``feature_noise`` in log
units: 0.14 for experts, 0.25 for novices, 0.15 for anyone else — ``FEATURE_NOISE``;
a remembered reference is perceived once, when felt). The *distance* to it is the
Euclidean distance of the features divided by per-feature spreads (``JND``).

The distance becomes a position on the scale by the range principle (Parducci): the
person anchors the scale on the nearest and farthest samples felt so far against the same
reference — "most realistic" is the nearest, "least" the farthest — and places the
current one linearly between them. Before the range is known, it is taken as
``RANGE_PRIOR`` = 3 JND units wide around what has been felt (the first trial lands
mid-scale). An absolute mapping (e.g. ``1 − d / 12``) put every aluminum rendering, 14–16
JND from the real block, on the floor and every rubber rendering near the top: nobody uses
a 1–10 scale that way when asked to rate eight sets against one block, and a study's
ratings then carried no information about the sets. The position is mapped onto the
protocol's scale through the person's own scale use: a gain in [0.7, 1.0] of the range, a
bias N(0, 0.4²) scale points and rating noise N(0, 0.6²) points, rounded and clipped. The
reference is what the protocol gives to compare with: the familiarization sample
(realism), or the real block of the current material, tapped once per block (factorial).

**Identification.** The person remembers rubber, wood and aluminum as the features of the
real blocks of the factorial protocol (tapped before the session, as in the study's
familiarization with real materials); each surface is named after the nearest remembered
material by pattern: the features of the three surfaces, centred on their mean, are
matched to the remembered materials' features, centred and scaled to the same spread (the
renderings are all softer than any real block, so absolute distances would name every
surface after the softest material); the assignment of the three names with the smallest
total weighted, JND-scaled squared difference is the answer (``ID_WEIGHT``: pitch counts
most, as frequency is the strongest cue to material in the vibration literature the papers
build on; jolt least, as it depends on how hard one taps). People get better with
practice: the perception noise of the surfaces is multiplied by ``ID_LEARNING`` = 0.85 per
repetition already done (the paper's Table 3: 35 of 42 answers correct overall, 12 of 14 on
the third attempt).

**Familiarization.** Each familiarization window is tapped afresh (its own seed from the
session's), and the reference is the mean of the two windows' perceived features.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from device import SimulatedHand
from protocols.kinds import REFERENCE, phase_kind

from .observer import draw_observer
from .participants import Responder

__all__ = ["SimulatedParticipant", "felt_features", "name_surfaces", "FEATURES", "JND"]

FEATURES = ("stop", "jolt", "pitch", "ring")
#: Per-feature spread that counts as one unit of perceived difference [log units].
JND = np.array([0.5, 0.6, 0.5, 0.6])
#: Below this the hand feels a push rather than a vibration [Hz].
HIGHPASS_HZ = 10.0
#: Weights of the features when naming a material: mostly by the pitch of the vibration,
#: then how it dies out; the jolt depends on how hard one taps, the stop on the spring.
ID_WEIGHT = np.array([0.5, 0.25, 1.0, 0.5])
#: Perceptual noise per feature [log units] by group; anyone else gets 0.15.
FEATURE_NOISE = {"expert": 0.14, "novice": 0.25}
#: Width of the range a person assumes before having felt it [JND units].
RANGE_PRIOR = 3.0
#: The onset window for pitch and ring-down spans this many periods of the strongest
#: vibration, within [ONSET_MIN_S, ONSET_MAX_S] [s].
ONSET_PERIODS = 1.5
ONSET_MIN_S, ONSET_MAX_S = 0.030, 0.150
#: Identification gets better with practice: perception noise is multiplied by this per
#: repetition already done (SPEC §2, Table 3: 35 of 42 correct, 12 of 14 on the third).
ID_LEARNING = 0.85
_VOID = np.full(4, np.nan)


def _dominant_hz(a: np.ndarray, rate: float) -> float:
    """Frequency of the strongest vibration in ``a`` [Hz], HIGHPASS_HZ–1500 Hz (a falling
    half-Hann taper, which keeps the onset where a fast-decaying ringing lives; zero-padded
    8x); HIGHPASS_HZ when there is none."""
    if len(a) < 4:
        return HIGHPASS_HZ
    freqs = np.fft.rfftfreq(8 * len(a), 1 / rate)
    band = (freqs >= HIGHPASS_HZ) & (freqs <= 1500.0)
    taper = np.hanning(2 * len(a))[len(a):]
    power = np.abs(np.fft.rfft((a - a.mean()) * taper, 8 * len(a)))[band]
    return float(freqs[band][np.argmax(power)]) if power.max() > 0 else HIGHPASS_HZ


def _pitch_ring(a: np.ndarray, m: int, rate: float) -> tuple[float, float]:
    """Pitch and ring-down of one contact's acceleration over an onset window of ``m``
    samples: the spectral centroid on a log-frequency axis of ``a[:m]`` weighted by
    exp(−t / (m/3)) [log Hz], and the log RMS ratio of ``a[:m/2]`` to ``a[m/2:3m/2]``."""
    freqs = np.fft.rfftfreq(8 * m, 1 / rate)
    band = (freqs >= HIGHPASS_HZ) & (freqs <= 1500.0)
    onset = np.exp(-3.0 * np.arange(m) / m)  # the first periods count most
    power = np.abs(np.fft.rfft(a[:m] * onset, 8 * m))[band] ** 2
    pitch = float(np.sum(power * np.log(freqs[band])) / np.sum(power)) if power.sum() > 0 \
        else math.log(HIGHPASS_HZ)
    k1, k2 = m // 2, (3 * m) // 2
    r1 = math.sqrt(float(np.mean(a[:k1] ** 2)) + 1e-12)
    r2 = math.sqrt(float(np.mean(a[k1:k2] ** 2)) + 1e-12)
    return pitch, math.log(r1 / r2)


def felt_features(result, window: float = 0.060) -> np.ndarray:
    """Median felt features of a window's contacts (see the module docstring).

    Parameters
    ----------
    result : WindowResult
        With the ``t`` and ``velocity`` traces, and ``accel`` (or ``true_accel``) where the
        device records it.
    window : float [s]
        How long after contact the vibration is judged.

    Returns
    -------
    ndarray (4,)
        ``stop``, ``jolt``, ``pitch``, ``ring`` [log units]; NaN when nothing was felt.
    """
    tr = result.traces
    if not result.contacts or not len(tr.get("t", ())):
        return _VOID.copy()
    from scipy import signal

    # the hand feels the stylus' true acceleration (the simulator reports it); the
    # accelerometer's reading, which clips at 50 g, stands in on other backends, and on a
    # device without one (the commercial devices' bridges) the acceleration its own
    # velocity estimate implies: what such a device can tell of the vibration
    t, vel = tr["t"], tr["velocity"]
    acc = tr.get("true_accel", tr.get("accel"))
    if acc is None:
        acc = np.gradient(np.asarray(vel, dtype=float), 1.0 / float(result.rate_hz))

    # vibration only: the slow push of the hand and the spring is felt as force, not as
    # vibration (zero-phase 2nd-order high-pass at HIGHPASS_HZ over the whole window)
    sos = signal.butter(2, HIGHPASS_HZ, "highpass", fs=float(result.rate_hz), output="sos")
    acc = signal.sosfiltfilt(sos, np.asarray(acc, dtype=float))
    rate = float(result.rate_hz)
    rows = []
    last = -np.inf
    for c in result.contacts:
        # a tap is the first contact of a stroke; rebounds within 100 ms belong to it
        first, last = c.t - last > 0.1, c.t
        i = int(np.searchsorted(t, c.t))
        if not first or c.velocity <= 0:
            continue
        # the onset window spans ONSET_PERIODS of the vibration, at least 30 ms: a slow
        # ringing (rubber's 18 Hz) cannot be heard in a window shorter than its period
        f0 = _dominant_hz(acc[i:i + int(ONSET_MAX_S * rate)], rate)
        m = int(np.clip(ONSET_PERIODS / f0, ONSET_MIN_S, ONSET_MAX_S) * rate)
        n = max(int(window * rate), int(1.5 * m))
        if i + n > len(t):
            continue
        a = acc[i:i + n] - acc[i:i + n].mean()
        v = vel[i:i + n]
        up = np.nonzero(v >= 0)[0]  # the encoder velocity is negative moving into the surface
        stop = (up[0] + 1) / rate if len(up) else n / rate
        jolt = np.max(np.abs(a[:int(window * rate)])) / c.velocity
        rows.append((math.log(stop), math.log(jolt + 1e-9), *_pitch_ring(a, m, rate)))
    if not rows:
        return _VOID.copy()
    return np.median(np.array(rows), axis=0)


def name_surfaces(felt: np.ndarray, remembered: np.ndarray, jnd: np.ndarray = JND
                  ) -> tuple[int, ...]:
    """Which remembered material each felt surface is named as: the relative judgement of
    the module docstring.

    The pattern of differences among the surfaces (centred features) is matched to the
    pattern among the remembered materials, scaled to the surfaces' spread (every rendering
    is softer than any real block, so absolute distances would call everything the softest
    material, and the renderings span a narrower range than the real blocks); the
    assignment with the least ``ID_WEIGHT``-weighted, JND-scaled squared difference wins.

    Parameters
    ----------
    felt : ndarray (n, 4)
        The surfaces' features as perceived [log units].
    remembered : ndarray (n, 4)
        The materials' features as remembered [log units].
    jnd : ndarray (4,)
        One unit of perceived difference per feature [log units].

    Returns
    -------
    tuple of int
        For surface ``i``, the index of the material it is named as (a permutation).
    """
    if np.shape(felt) != np.shape(remembered):
        raise ValueError(f"{np.shape(felt)[0]} surfaces felt against {np.shape(remembered)[0]} "
                         f"materials remembered (feature arrays {np.shape(felt)} and "
                         f"{np.shape(remembered)}): one surface per material")
    felt_c, mem_c = felt - felt.mean(0), remembered - remembered.mean(0)
    spread = np.where(mem_c.std(0) > 0, felt_c.std(0) / np.maximum(mem_c.std(0), 1e-12), 1.0)
    mem_c = mem_c * spread
    n = len(felt)
    cost = {(i, j): float(np.nansum((ID_WEIGHT * (felt_c[i] - mem_c[j]) / jnd) ** 2))
            for i in range(n) for j in range(n)}
    return min(itertools.permutations(range(n)),
               key=lambda p: sum(cost[i, j] for i, j in enumerate(p)))


@dataclass(frozen=True)
class Person:
    """One simulated person's constants (drawn once from their seed)."""

    tap_speed: float  # m/s
    tap_sd: float  # m/s
    gain: float  # share of the rating range used
    bias: float  # scale points
    rating_noise: float  # scale points
    feature_noise: float  # log units
    grasp: float = 1.0  # factor on the hand's stiffness and damping
    rhythm: float = 1.0  # factor on the dwell and pause between taps

    @classmethod
    def draw(cls, rng: np.random.Generator, group: str = "") -> Person:
        person = cls(tap_speed=float(np.clip(rng.normal(0.11, 0.02), 0.05, 0.2)), tap_sd=0.025,
                     gain=float(rng.uniform(0.7, 1.0)), bias=float(rng.normal(0.0, 0.4)),
                     rating_noise=0.6, feature_noise=FEATURE_NOISE.get(group, 0.15))
        # drawn last, so the constants above stay those of the same seed
        return replace(person, grasp=float(np.exp(np.clip(rng.normal(0.0, 0.2), -0.5, 0.5))),
                       rhythm=float(rng.uniform(0.6, 1.6)))


class SimulatedParticipant(Responder):
    """Taps, feels and answers as the model in the module docstring.

    Parameters
    ----------
    protocol : Protocol
        The session's protocol (for the references to compare with).
    seed : int
        Session seed; the person's constants come from it alone.
    group : str
        ``expert`` (used to haptic devices: perceives with less noise), ``novice``
        (more), or anything else (in between); see ``FEATURE_NOISE``.
    """

    name = "simulated"
    stateful = True  # remembers references and the range of what it felt

    def __init__(self, protocol, seed: int, group: str = "",
                 discrimination: Mapping[str, float] | None = None):
        self.protocol = protocol
        self._mem_rng = np.random.default_rng(np.random.SeedSequence([seed, 7919]))
        self.person = Person.draw(self._mem_rng, group)
        #: how it tells two renderings apart in a forced choice (app.observer): drawn from
        #: its own stream, so the constants above stay those of the same seed
        self.observer = draw_observer(np.random.default_rng(
            np.random.SeedSequence([seed, 7919, 57])), discrimination)
        self.memory: dict[str, np.ndarray] = {}
        self._device = None
        self._familiar: list[np.ndarray] = []
        self._real_blocks = None
        self._context: dict[str, list[float]] = {}  # distances felt so far, per reference

    # ---------------------------------------------------------------- tapping
    def before_window(self, trial, sample_id, device, rng) -> None:
        self._device = device
        self._hold(device)

    @property
    def hand(self) -> SimulatedHand:
        """How this person holds and taps the stylus."""
        p = self.person
        return SimulatedHand(grasp=p.grasp, tap_speed=p.tap_speed, tap_speed_sd=p.tap_sd,
                             rhythm=p.rhythm)

    def _hold(self, device) -> None:
        """Take the stylus with this person's grasp and tapping (a simulated device only)."""
        device.set_simulated_hand(self.hand)

    def keep_tapping(self) -> bool:
        return len(self._familiar) < 2  # two familiarization windows

    def after_window(self, trial, sample_id, result) -> None:
        if trial.kind == REFERENCE:  # a real block, tapped to compare with: remember it
            f = felt_features(result)
            if np.all(np.isfinite(f)):
                self.memory[sample_id] = self._perceive(f, self._mem_rng)
            return
        if phase_kind(trial.kind).windows == "until_done":  # familiarization
            f = felt_features(result)
            if np.all(np.isfinite(f)):
                self._familiar.append(self._perceive(f, self._mem_rng))
                self.memory["reference"] = np.mean(self._familiar, axis=0)

    # ---------------------------------------------------------------- judging
    def _feel_scene(self, key: str, scene) -> np.ndarray:
        """Tap a reference (a real block beside the device) once and remember it."""
        if key not in self.memory and self._device is not None:
            dev = self._device
            self._hold(dev)
            dev.load_scene(scene)
            dev.home()
            felt = felt_features(dev.run_window(3.0, timeout=30.0))
            dev.zero()  # off again, as the runner leaves it between windows
            self.memory[key] = self._perceive(felt, self._mem_rng)
        return self.memory.get(key, _VOID)

    def _reference(self, trial) -> tuple[str, np.ndarray]:
        """The key and remembered features of what this trial is compared with."""
        sample = self.protocol.samples[trial.samples[0]]
        if sample.reference is not None:
            ref = self.protocol.samples[sample.reference]
            return ref.id, self._feel_scene(ref.id, ref.scene)
        if "reference" not in self.memory and self.protocol.phases:
            # a resumed session: tap the familiarization sample again before going on
            free = [p for p in self.protocol.phases
                    if phase_kind(p.kind).windows == "until_done"]
            if free:
                ref = self.protocol.samples[free[0].samples[0]]
                return "reference", self._feel_scene("reference", ref.scene)
        return "reference", self.memory.get("reference", _VOID)

    def _perceive(self, f: np.ndarray, rng, practice: int = 0) -> np.ndarray:
        """``f`` with this person's perception noise, smaller after ``practice``
        repetitions of the same task (``ID_LEARNING``)."""
        return f + rng.normal(0.0, self.person.feature_noise * ID_LEARNING ** practice, f.shape)

    def distance(self, felt: np.ndarray, remembered: np.ndarray, rng) -> float:
        """JND-scaled distance between what is felt now (perceived with fresh noise) and
        what is remembered (perceived once, when it was felt) [JND units]; NaN when
        nothing can be compared."""
        a = self._perceive(felt, rng)
        ok = np.isfinite(a) & np.isfinite(remembered)
        if not ok.any():
            return math.nan
        return math.sqrt(float(np.sum(((a[ok] - remembered[ok]) / JND[ok]) ** 2)))

    def position(self, key: str, d: float) -> float:
        """Where distance ``d`` sits in the range felt so far against reference ``key``:
        1 at the nearest, 0 at the farthest (range principle; see the module docstring).
        A distance that cannot be computed (nothing felt) sits at the farthest."""
        ctx = self._context.setdefault(key, [])
        if math.isnan(d):
            return 0.0
        ctx.append(d)
        lo, hi = min(ctx), max(ctx)
        if hi - lo < RANGE_PRIOR:
            mid = (lo + hi) / 2
            lo, hi = mid - RANGE_PRIOR / 2, mid + RANGE_PRIOR / 2
        return float(np.clip((hi - d) / (hi - lo), 0.0, 1.0))

    def rate(self, trial, scale, result, rng) -> tuple[int, float]:
        key, ref = self._reference(trial)
        s = self.position(key, self.distance(felt_features(result), ref, rng))
        lo, hi = scale.min, scale.max
        mid, span = (lo + hi) / 2, hi - lo
        y = mid + self.person.gain * span * (s - 0.5) + self.person.bias \
            + rng.normal(0.0, self.person.rating_noise)
        return int(np.clip(round(y), lo, hi)), float(rng.lognormal(math.log(1.5), 0.3))

    def answer(self, response, question, rng) -> tuple[Any, float]:
        """As the response declares (``response.simulated``), from this model's perception
        and memory (its public methods)."""
        return response.simulated(self, question, rng)

    def distances(self, trial, results, rng) -> list[float]:
        """For each window of ``results``, how far what was felt lay from what it remembers
        of real contact (the familiarization block, or the samples' real reference), each
        perceived with fresh noise [JND units]; NaN where nothing could be compared."""
        _key, ref = self._reference(trial)
        return [self.distance(felt_features(r), ref, rng) for r in results]

    def judge_larger(self, parameter: str, values, rng) -> tuple[int, float]:
        """Which of two renderings has the larger ``parameter`` (their ``values``, as the
        device was asked to render them), as its observer says (:mod:`app.observer`)."""
        return self.observer.judge(parameter, values, rng), self.response_time(1.2, rng)

    @staticmethod
    def response_time(median: float, rng) -> float:
        """A response time around ``median`` [s] (log-normal, 0.3 in log units)."""
        return float(rng.lognormal(math.log(median), 0.3))

    def identify(self, trial, choices, results, rng) -> tuple[list[str], float]:
        # each name's real block: the protocol's reference of the surface of that name (tapped
        # before the test, and remembered then)
        refs = {}
        for c in choices:
            ref_id = self.protocol.samples[c].reference if c in self.protocol.samples else None
            if ref_id is None:
                if self._real_blocks is None:  # older protocols: the factorial's real blocks
                    from protocols import load_protocol

                    self._real_blocks = load_protocol("factorial").samples
                refs[c] = (f"material:{c}", self._real_blocks[f"{c}-real"].scene)
            else:
                refs[c] = (ref_id, self.protocol.samples[ref_id].scene)
        practice = max(int(getattr(trial, "repetition", 1)) - 1, 0)
        felt = np.array([self._perceive(felt_features(r), rng, practice) for r in results])
        mem = np.array([self._feel_scene(*refs[c]) for c in choices])
        best = [choices[j] for j in name_surfaces(felt, mem)]
        return [str(c) for c in best], float(rng.uniform(4.0, 10.0))

    def debrief(self) -> str:
        p = self.person
        return (f"simulated participant (a rehearsal model, not a person): taps at "
                f"{p.tap_speed:.3f} ± {p.tap_sd:.3f} m/s; rates by the distance of stop time, "
                f"jolt, pitch and ring-down from the reference, placed on the range felt so "
                f"far; perception noise {p.feature_noise:.2f}; scale gain {p.gain:.2f}, "
                f"bias {p.bias:+.2f}")
