"""The measuring parts of ``hapticlab bench factorial``: the noise-free panel's verdicts
(computed by hand here), the identification drawn by the participant's own naming rule, and
one measured cause on the simulated device."""

import math

import numpy as np
import pytest

from app.participant_model import JND, name_surfaces
from benchmarks import factorial

LEVELS = ("LLL", "LLH", "LHL", "LHH", "HLL", "HLH", "HHL", "HHH")


def _felt(pitch_by_set: dict[str, float]) -> dict[str, np.ndarray]:
    """Every material's real block at 0 and its sets differing in pitch only [log units]."""
    out = {}
    for mat in factorial.MATERIALS:
        out[f"{mat}-real"] = np.zeros(4)
        for s in LEVELS:
            out[f"{mat}-{s}"] = np.array([0.0, 0.0, pitch_by_set[s], 0.0])
    return out


def test_the_nearest_set_and_each_factors_effect_by_hand():
    # pitch 0.5 log units (1 JND) per low frequency level, 0.25 (0.5 JND) per low slope level:
    # the high frequency is 1 JND nearer, the high slope 0.5, the decay does nothing
    pitch = {s: 0.5 * (s[0] == "L") + 0.25 * (s[2] == "L") for s in LEVELS}
    v = factorial.judge(_felt(pitch), JND)["aluminum"]
    assert set(v["order"][:2]) == {"HLH", "HHH"}  # both at the block: 0 JND
    assert v["distances"]["LLL"] == pytest.approx(1.5)
    assert v["effects"]["frequency"] == pytest.approx(1.0)
    assert v["effects"]["slope"] == pytest.approx(0.5)
    assert v["effects"]["decay"] == pytest.approx(0.0, abs=1e-12)
    assert v["first"] == "frequency" and not v["first_is_paper"]  # the paper: slope
    assert v["paper_best_rank"] <= 2 and abs(v["ring_decay_high_minus_low"]) < 1e-12


def test_a_factor_under_the_detectable_effect_is_not_counted_as_the_papers():
    pitch = {s: 0.05 * (s[2] == "L") for s in LEVELS}  # slope alone, 0.1 JND
    v = factorial.judge(_felt(pitch), JND)["aluminum"]
    assert v["first"] == "slope" and abs(v["effects"]["slope"]) < factorial.DETECTABLE_JND
    assert not v["first_is_paper"]


def test_naming_follows_the_pattern_not_the_level():
    """Surfaces softer than every block (all features −3) but in the blocks' pattern are named
    as the blocks; the pattern permuted, the naming follows it."""
    blocks = np.array([[0.0, 0.0, 3.0, 0.0], [0.0, 0.0, 5.0, 0.0], [0.0, 0.0, 7.0, 0.0]])
    assert name_surfaces(blocks - 3.0, blocks) == (0, 1, 2)
    assert name_surfaces(blocks[[2, 0, 1]] * 0.5, blocks) == (2, 0, 1)
    with pytest.raises(ValueError, match="2 surfaces felt against 3 materials"):
        name_surfaces(blocks[:2], blocks)


def test_identification_counts_swaps_by_pair():
    """Wood and rubber felt alike, aluminum far in pitch: the swaps fall on rubber–wood."""
    felt = _felt({s: 0.0 for s in LEVELS})
    felt["rubber-real"] = np.array([0.0, 0.0, 3.0, 0.0])
    felt["wood-real"] = np.array([0.0, 0.0, 3.1, 0.0])
    felt["aluminum-real"] = np.array([0.0, 0.0, 6.0, 0.0])
    for mat, p in (("rubber", 3.0), ("wood", 3.1), ("aluminum", 6.0)):
        felt[f"{mat}-{factorial.PAPER_BEST[mat]}"] = np.array([0.0, 0.0, p, 0.0])
    out = factorial.identify(felt, JND)
    assert out["most_confused"] == "rubber–wood" and out["confusion_is_paper"]
    assert set(out["swaps"]) == {"rubber–wood"}
    assert 0.3 < out["all_right"] < 0.7  # 0.1 log units apart under 0.15 of noise: a coin


def test_a_set_nothing_was_felt_of_ranks_last_not_first():
    pitch = {s: 0.5 * (s[0] == "L") for s in LEVELS}
    felt = _felt(pitch)
    felt["wood-HHH"] = np.full(4, np.nan)
    v = factorial.judge(felt, JND)["wood"]
    assert v["order"][-1] == "HHH" and math.isnan(v["distances"]["HHH"])
    assert v["order"][0] != "HHH"


def test_a_decay_difference_alone_steepens_the_ring_down():
    """The participant's ring-down of a sinusoid alone (its own onset window T): ×1.5 the
    decay reads steeper, more so at 30 Hz (T = 50 ms) than at 200 Hz (30 ms). By hand, the
    two RMS windows [0, T/2] and [T/2, 3T/2] have centres 0.75 T apart, so 60 → 90/s adds
    about 30 × 0.0375 ≈ 1.1 log units at 30 Hz and at most 30 × 0.0225 ≈ 0.7 at 200 Hz
    (less where the envelope weights each window towards its start).
    Measured: 1.19 at 30 Hz, 0.49 at 200 Hz."""
    lo = factorial.ring_alone(30.0, (60.0, 90.0))
    hi = factorial.ring_alone(200.0, (60.0, 90.0))
    assert 0.8 < lo < 1.6 and 0.3 < hi < 0.7
    assert abs(factorial.ring_alone(30.0, (60.0, 60.0))) < 1e-12


def test_seeds_are_parsed_or_refused_by_name():
    from app.errors import UsageError
    from benchmarks._common import parse_seeds

    assert parse_seeds(None, [1, 2]) == [1, 2] and parse_seeds("3, 4", [1]) == [3, 4]
    for bad in ("x", ",", "-1"):
        with pytest.raises(UsageError, match="--seeds"):
            parse_seeds(bad, [1])


def test_the_resonance_of_the_transmission():
    from device.sim.params import DeviceParams, HandParams

    dev, hand = DeviceParams(), HandParams()
    # by hand: 45 g against 110 g, 31.9 g reduced, on 21 kN/m: √(21000/0.0319355)/2π
    assert factorial.resonance_hz(dev, hand) == pytest.approx(129.06, abs=0.05)


def test_a_stiffer_transmission_gives_aluminums_300_hz_sets_their_jolt():
    """The cause measured on the simulated device (seed 1, 2 windows each): on the default
    device (~129 Hz) the 300-Hz set HHH is felt weaker than the 200-Hz LHH — the jolt more
    than 1 JND lower, so the panel prefers the low frequency; with the transmission 4× stiffer
    (~258 Hz) the 300-Hz set is felt as strong or stronger. Measured: −1.58 and +0.34 JND
    (and its pitch −0.36 and +0.43 JND: on the default device it rings at the resonance)."""
    from dataclasses import replace

    from device.sim.params import DeviceParams
    from protocols import load_protocol

    samples = load_protocol("factorial").samples
    gap = {}
    for times in (1.0, 4.0):
        dev = replace(DeviceParams(), link_stiffness=DeviceParams().link_stiffness * times)
        hi, lo = (factorial.feel(samples[k].scene, [1], dev, None, windows=2)
                  for k in ("aluminum-HHH", "aluminum-LHH"))
        gap[times] = (hi[1] - lo[1]) / JND[1]
    assert gap[1.0] < -1.0 and gap[4.0] > -0.2, gap
