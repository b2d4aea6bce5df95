"""Paired comparisons (the comparison kind's analysis) against R's binom.test and p.adjust,
and by hand."""

import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from analysis.stats import StatsError, order_bias, pair_preferences
from analysis.study import choice_scores


def _choices(seed=3, n_people=4):
    """Every ordered pair of four samples once per person; the choice leans towards the
    earlier sample of the list by a known amount."""
    rng = np.random.default_rng(seed)
    levels = ["a", "b", "c", "d"]
    rows = []
    for p in range(n_people):
        for i, x in enumerate(levels):
            for j, y in enumerate(levels):
                if i != j:
                    lean = 0.5 + 0.12 * (j - i)  # P(x chosen over y)
                    rows.append({"participant": f"P{p}", "first": x, "second": y,
                                 "chosen": x if rng.random() < lean else y})
    return pd.DataFrame(rows), levels


def test_a_pair_counts_both_orders_and_is_tested_by_hand():
    d = pd.DataFrame({"first": ["a", "b", "a", "b"], "second": ["b", "a", "b", "a"],
                      "chosen": ["a", "a", "b", "a"]})
    r = pair_preferences(d, "first", "second", "chosen").iloc[0]
    assert (r["A"], r["B"], r["n"], r["chose_A"], r["A_first"]) == ("a", "b", 4, 3, 2)
    # P(X >= 3) + P(X <= 1) for X ~ Binomial(4, 1/2): (1 + 4 + 4 + 1) / 16
    assert r["p_unc"] == pytest.approx(10 / 16, rel=1e-12)
    assert r["p_corr"] == pytest.approx(10 / 16, rel=1e-12)  # one pair: nothing to correct


@pytest.mark.integration
@pytest.mark.r
@pytest.mark.skipif(shutil.which("Rscript") is None,
                    reason="R missing: `make test` installs r-base-core")
def test_every_pair_and_the_order_bias_match_r():
    d, levels = _choices()
    ours = pair_preferences(d, "first", "second", "chosen", levels=levels)
    ks = ",".join(str(k) for k in ours["chose_A"])
    ns = ",".join(str(n) for n in ours["n"])
    ob = order_bias(d, "first", "second", "chosen").iloc[0]
    # the R calls, beside the values they give
    script = (f"k <- c({ks}); n <- c({ns}); "
              "p <- mapply(function(k, n) binom.test(k, n, 0.5)$p.value, k, n); "
              "cat(sprintf('%.17g', p), sep='\\n'); "
              "cat(sprintf('%.17g', p.adjust(p, method = 'holm')), sep='\\n'); "
              f"cat(sprintf('%.17g', binom.test({ob['chose_first']}, {ob['n']}, 0.5)$p.value),"
              " sep='\\n')")
    out = subprocess.run(["Rscript", "-e", script], capture_output=True, text=True,
                         check=True, timeout=120).stdout.split()
    r = [float(x) for x in out]
    m = len(ours)
    np.testing.assert_allclose(ours["p_unc"], r[:m], rtol=1e-10)
    np.testing.assert_allclose(ours["p_corr"], r[m:2 * m], rtol=1e-10)
    assert ob["p_unc"] == pytest.approx(r[2 * m], rel=1e-10)
    assert m == 6 and (ours["n"] == 8).all()  # 4 people × both orders of each of 6 pairs


def test_scores_per_sample_and_what_cannot_be_analysed():
    d, levels = _choices()
    rows = d.assign(sample=d["first"] + "+" + d["second"], answer=d["chosen"], valid=True)
    res = choice_scores(rows, levels)
    wins = {r["sample"]: r["wins"] for r in res["samples"]}
    assert wins == d["chosen"].value_counts().to_dict()
    assert all(r["n"] == 24 for r in res["samples"])  # 4 people × 3 others × 2 orders
    assert [r["prop_won"] for r in res["samples"]] == sorted(
        [r["prop_won"] for r in res["samples"]], reverse=True)
    assert (res["n_subjects"], res["n_choices"]) == (4, 48)
    bad = d.copy()
    bad.loc[0, "chosen"] = "z"
    with pytest.raises(StatsError, match="name neither sample of their pair, first: 'z'"):
        pair_preferences(bad, "first", "second", "chosen")
    with pytest.raises(StatsError, match="not among the levels"):
        pair_preferences(d, "first", "second", "chosen", levels=["a", "b"])
