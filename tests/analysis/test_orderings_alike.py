"""``hapticlab bench orderings``' test of the paper's "not distinguishable" pairs: an
equivalence test on the rows a realism analysis uses, not a non-significant t-test."""

import numpy as np
import pandas as pd

from benchmarks import orderings


def _rows(shift: dict[str, float], n: int = 9, seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    samples = ["wood_on_foam", "matched_firm", "matched_soft", "firm_spring", "foam"]
    rows = []
    for p in range(n):
        base = rng.normal(4.0, 0.8)
        for s in samples:
            rows.append({"protocol": "realism", "phase": "testing", "valid": True,
                         "participant": f"P{p:02d}", "sample": s,
                         "rating": base + shift.get(s, 0.0) + rng.normal(0, 0.3)})
    return pd.DataFrame(rows)


def test_pairs_a_fraction_of_a_point_apart_are_equivalent_and_a_two_point_gap_is_not():
    out = {a["pair"]: a for a in orderings._alike(_rows({"firm_spring": 2.0}))}
    assert list(out) == [f"{a}–{b}" for a, b in orderings.PAPER_ALIKE]
    alike = out["matched_firm–wood_on_foam"]
    assert alike["equivalent"] and alike["bound_reached"] < orderings.ALIKE_BOUND
    apart = out["firm_spring–foam"]
    assert not apart["equivalent"] and apart["p_ttest"] < 0.001
    assert apart["verdict"].startswith("not shown alike")


def test_a_pair_with_the_same_difference_for_everyone_is_said_to_have_no_test():
    d = _rows({})
    d.loc[d["sample"] == "foam", "rating"] = d.loc[d["sample"] == "firm_spring",
                                                   "rating"].to_numpy() - 0.5
    out = {a["pair"]: a for a in orderings._alike(d)}
    assert out["firm_spring–foam"]["verdict"] == "no test: difference 0.5 for every subject"


def test_a_sample_nobody_rated_validly_is_said_to_have_no_test():
    d = _rows({})
    d.loc[d["sample"] == "foam", "valid"] = False
    out = {a["pair"]: a for a in orderings._alike(d)}
    assert out["firm_spring–foam"]["verdict"] == "no test: foam has no valid rating"
    assert out["matched_firm–wood_on_foam"]["equivalent"]
