"""Studies for the R reference check, generated from recorded seeds.

Each is a long table in the columns of hapticlab's ``long.csv`` export (participant,
group, block, sample, the factorial's factors, repetition, rating), written to CSV for
``reference.R`` and analysed by hapticlab from the same rows. They are built to reach what
the papers' clean data do not: tied cell means (thirds of integer ratings), missing cells,
a participant who gave one material the same rating throughout, unequal repetitions,
two participant groups, and a small study whose Wilcoxon tests are exact.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

SAMPLES = [f"s{i:02d}" for i in range(1, 12)]  # 11 samples, as the realism protocol
MATERIALS = ["rubber", "wood", "aluminum"]
FACTORS = ["frequency", "decay", "slope"]


def _oneway(seed: int, n: int, reps: int, samples=SAMPLES) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    effect = np.linspace(-1.8, 1.8, len(samples))
    rows = []
    for p in range(n):
        offset = rng.normal(0, 0.7)
        for s, e in zip(samples, effect, strict=True):
            for r in range(reps):
                y = np.clip(np.rint(4 + e + offset + rng.normal(0, 1.0)), 1, 7)
                rows.append({"participant": f"P{p + 1:02d}", "group": "", "block": "",
                             "sample": s, "repetition": r + 1, "rating": int(y)})
    return pd.DataFrame(rows)


def oneway_clean() -> pd.DataFrame:
    """12 participants × 11 samples × 3 repetitions, 1–7."""
    return _oneway(2711, 12, 3)


def oneway_messy() -> pd.DataFrame:
    """The clean design made awkward: P03 lacks two samples (left out listwise), P05 rated
    s04 once and s09 twice, P07 rated every sample 4 but s11 (ties everywhere), and two
    groups (expert P01–P06, novice P07–P12) for the sample × group model."""
    d = _oneway(9137, 12, 3)
    d = d[~((d.participant == "P03") & d["sample"].isin(["s02", "s10"]))]
    d = d[~((d.participant == "P05") & (d["sample"] == "s04") & (d.repetition > 1))]
    d = d[~((d.participant == "P05") & (d["sample"] == "s09") & (d.repetition > 2))]
    d.loc[(d.participant == "P07") & (d["sample"] != "s11"), "rating"] = 4
    d["group"] = np.where(d.participant.str[1:].astype(int) <= 6, "expert", "novice")
    return d.reset_index(drop=True)


def oneway_small() -> pd.DataFrame:
    """7 participants × 4 samples × 5 repetitions: few tied means, so exact Wilcoxon p."""
    return _oneway(45, 7, 5, samples=SAMPLES[:4])


def factorial() -> pd.DataFrame:
    """10 participants, 3 materials × 2³ sets × 3 repetitions, 1–10; P04 rated every
    aluminum set 5 (a constant block); P11 reached only the wood block and rated 2 of its 8
    sets, both 6 (missing sets, left out of wood's ANOVA as R's aov_ez does; never reached
    the other blocks)."""
    rng = np.random.default_rng(3301)
    rows = []
    for p in range(10):
        offset = rng.normal(0, 1.0)
        for m in MATERIALS:
            for levels in itertools.product(("low", "high"), repeat=3):
                code = "".join(x[0].upper() for x in levels)
                e = (0.8 * (levels[0] == "high") - 0.5 * (levels[1] == "high")
                     + 0.4 * (levels[0] == "high") * (levels[2] == "low"))
                for r in range(3):
                    y = np.clip(np.rint(5 + e + offset + rng.normal(0, 1.4)), 1, 10)
                    rows.append({"participant": f"P{p + 1:02d}", "group": "", "block": m,
                                 "sample": f"{m}_{code}", **dict(zip(FACTORS, levels, strict=True)),
                                 "repetition": r + 1, "rating": int(y)})
    for code in ("LLL", "HHH"):
        levels = ["low" if c == "L" else "high" for c in code]
        rows.append({"participant": "P11", "group": "", "block": "wood",
                     "sample": f"wood_{code}", **dict(zip(FACTORS, levels, strict=True)),
                     "repetition": 1, "rating": 6})
    d = pd.DataFrame(rows)
    d.loc[(d.participant == "P04") & (d.block == "aluminum"), "rating"] = 5
    return d


def crossed_2x3() -> pd.DataFrame:
    """A design beyond the papers': 2 × 3 within (hand × texture), 12 participants, 2
    repetitions, 1–7; texture and the interaction have 2 degrees of freedom, so they get
    sphericity tests and corrections."""
    rng = np.random.default_rng(623)
    rows = []
    for p in range(12):
        offset = rng.normal(0, 0.8)
        slope = rng.normal(0, 0.6)  # participants differ in the texture effect: ε < 1
        for hand in ("left", "right"):
            for k, tex in enumerate(("smooth", "ridged", "coarse")):
                for r in range(2):
                    e = 0.5 * (hand == "right") + (0.6 + slope) * k + 0.3 * k * (hand == "left")
                    y = np.clip(np.rint(3 + e + offset + rng.normal(0, 0.9)), 1, 7)
                    rows.append({"participant": f"P{p + 1:02d}", "group": "", "block": "",
                                 "sample": f"{hand}_{tex}", "hand": hand, "texture": tex,
                                 "repetition": r + 1, "rating": int(y)})
    return pd.DataFrame(rows)


def _valid(make):
    def wrapped() -> pd.DataFrame:
        return make().assign(valid=True)
    wrapped.__doc__ = make.__doc__
    return wrapped


STUDIES = {name: _valid(make) for name, make in (
    ("oneway_clean", oneway_clean), ("oneway_messy", oneway_messy),
    ("oneway_small", oneway_small), ("factorial", factorial), ("crossed_2x3", crossed_2x3))}
