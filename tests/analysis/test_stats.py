"""Statistics checked against values computed independently (call or formula beside each)."""


import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from statsmodels.stats.multitest import multipletests

from analysis import (
    StatsError,
    equivalence_ttests,
    identification_scores,
    p_adjust,
    pairwise_ttests,
    preflight,
    rm_anova,
    zscore_by_subject,
)

# 6 subjects × 4 conditions
Y = np.array([[5, 4, 6, 3], [6, 5, 7, 4], [4, 4, 5, 2], [7, 5, 6, 5], [5, 3, 6, 3],
              [6, 6, 7, 3]], float)
ONE = pd.DataFrame([{"subj": f"S{i}", "cond": f"c{j}", "y": Y[i, j]}
                    for i in range(6) for j in range(4)])


def test_one_way_matches_pingouin():
    a = rm_anova(ONE, "y", "cond", "subj").iloc[0]
    # pingouin 0.7.0: pg.rm_anova(data=ONE, dv="y", within="cond", subject="subj",
    #                             correction=True, detailed=True, effsize="np2")
    assert a["SS"] == pytest.approx(27.458333333333336, rel=1e-12)
    assert a["DF"] == 3
    assert a["F"] == pytest.approx(23.70503597122302, rel=1e-12)
    assert a["p_unc"] == pytest.approx(6.054942251450185e-06, rel=1e-9)
    assert a["np2"] == pytest.approx(0.8258145363408522, rel=1e-12)
    assert a["eps_gg"] == pytest.approx(0.6029710077083917, rel=1e-10)
    assert a["p_gg"] == pytest.approx(0.0003020198723841498, rel=1e-8)
    assert a["W_mauchly"] == pytest.approx(0.18530699998771252, rel=1e-10)
    # pg.sphericity(...): chi2 = 6.274703987931807, dof = 5, pval = 0.2950663273085372
    assert a["p_spher"] == pytest.approx(0.2950663273085372, rel=1e-9)
    # pg.rm_anova(..., effsize="ng2")["ng2"][0]
    assert a["ng2"] == pytest.approx(0.5889186773905273, rel=1e-12)
    # pg.epsilon(data=ONE, dv="y", within="cond", subject="subj", correction="hf")
    assert a["eps_hf"] == pytest.approx(0.9248132065876458, rel=1e-10)


def test_one_way_by_hand():
    """SS_cond = n·Σ(column mean − grand mean)²; SS_error = SS_total − SS_subj − SS_cond."""
    n, k = Y.shape
    g = Y.mean()
    ss_c = n * ((Y.mean(0) - g) ** 2).sum()
    ss_s = k * ((Y.mean(1) - g) ** 2).sum()
    ss_e = ((Y - g) ** 2).sum() - ss_s - ss_c
    F = (ss_c / (k - 1)) / (ss_e / ((k - 1) * (n - 1)))
    a = rm_anova(ONE, "y", "cond", "subj")
    assert a.iloc[0]["SS"] == pytest.approx(ss_c) and a.iloc[0]["SS_err"] == pytest.approx(ss_e)
    assert a.iloc[0]["F"] == pytest.approx(F)


# 5 subjects, 2×2×2, frequency raises y by 0.8
Z = np.array([[[[0.0, 0.3], [-0.27, -0.89]], [[-0.45, -0.99], [0.06, 1.34]]],
              [[[-0.49, -0.62], [0.49, 0.36]], [[0.11, -0.93], [-0.03, 0.7]]],
              [[[-1.34, -0.46], [-1.9, -1.29]], [[-1.84, -0.24], [-1.27, 0.27]]],
              [[[0.16, -0.19], [-2.52, -0.54]], [[-0.05, 0.11], [-1.53, -0.48]]],
              [[[-0.98, -0.81], [1.06, -0.81]], [[-0.03, 0.88], [-0.58, -0.11]]]])
THREE = pd.DataFrame([{"subj": s, "frequency": f, "decay": d, "slope": sl,
                       "y": Z[s, i, j, k] + 0.8 * (f == "H")}
                      for s in range(5) for i, f in enumerate("LH") for j, d in enumerate("LH")
                      for k, sl in enumerate("LH")])


def test_three_way_matches_statsmodels():
    # statsmodels 0.15: AnovaRM(THREE, "y", "subj", within=["frequency", "decay", "slope"])
    #                   .fit().anova_table
    ref = {"frequency": (181.675744, 0.000175), "decay": (0.000127, 0.991532),
           "slope": (1.930445, 0.237051), "frequency * decay": (0.302275, 0.611715),
           "frequency * slope": (2.883983, 0.164696), "decay * slope": (0.406415, 0.558458),
           "frequency * decay * slope": (1.804921, 0.250273)}
    a = rm_anova(THREE, "y", ["frequency", "decay", "slope"], "subj").set_index("Source")
    for src, (F, p) in ref.items():
        assert a.loc[src, "F"] == pytest.approx(F, abs=1e-5), src
        assert a.loc[src, "p_unc"] == pytest.approx(p, abs=1e-6), src
        assert a.loc[src, "DF"] == 1
    # partial η² = SS / (SS + SS_error) row by row
    f = a.loc["frequency"]
    assert f["np2"] == pytest.approx(f["SS"] / (f["SS"] + f["SS_err"]))
    assert f["F"] == pytest.approx(f["MS"] / f["MS_err"]) and f["DF_err"] == 4
    assert len(a) == 7 and not a.isna().any().any()


def test_pairwise_matches_scipy_and_pingouin():
    pw = pairwise_ttests(ONE, "y", "cond", "subj", "holm")
    assert len(pw) == 6
    for r in pw.itertuples():
        res = stats.ttest_rel(Y[:, int(r.A[1])], Y[:, int(r.B[1])])  # scipy, independent
        assert r.t == pytest.approx(res.statistic) and r.p_unc == pytest.approx(res.pvalue)
        d = Y[:, int(r.A[1])] - Y[:, int(r.B[1])]
        assert r.dz == pytest.approx(d.mean() / d.std(ddof=1))
        h = stats.t.ppf(0.975, 5) * d.std(ddof=1) / math.sqrt(6)
        assert (r.ci_low, r.ci_high) == pytest.approx((d.mean() - h, d.mean() + h))
    # pingouin 0.7.0: pg.pairwise_tests(data=ONE, dv="y", within="cond", subject="subj",
    #                                  padjust="holm")["p_corr"]
    assert pw["p_corr"].to_numpy() == pytest.approx(
        [0.122578, 0.122578, 0.000288, 0.016419, 0.122578, 0.004410], abs=1e-6)


@pytest.mark.parametrize("a, b, bound, p_pingouin", [
    # pingouin 0.7.0: pg.tost(Y[:, a], Y[:, b], bound=bound, paired=True)["pval"]
    ("c0", "c1", 1.0, 0.5), ("c0", "c1", 2.0, 0.020429701929647926),
    ("c0", "c2", 1.5, 0.0272450496711881), ("c1", "c0", 2.0, 0.020429701929647926)])
def test_equivalence_matches_pingouin_and_its_definition(a, b, bound, p_pingouin):
    eq = equivalence_ttests(ONE, "y", "cond", "subj", bound, pairs=[(a, b)]).iloc[0]
    assert eq.p == pytest.approx(p_pingouin, rel=1e-9)
    d = Y[:, int(a[1])] - Y[:, int(b[1])]
    # scipy, independently: the two one-sided tests against ±bound
    lo = stats.ttest_1samp(d, -bound, alternative="greater")
    hi = stats.ttest_1samp(d, bound, alternative="less")
    assert (eq.t_lower, eq.t_upper) == pytest.approx((lo.statistic, hi.statistic))
    assert (eq.p_lower, eq.p_upper) == pytest.approx((lo.pvalue, hi.pvalue))
    h = stats.t.ppf(0.95, 5) * d.std(ddof=1) / math.sqrt(6)  # the 90 % CI
    assert (eq.ci_low, eq.ci_high) == pytest.approx((d.mean() - h, d.mean() + h))
    assert eq.bound_reached == pytest.approx(max(abs(d.mean() - h), abs(d.mean() + h)))
    assert eq.equivalent == (eq.p < 0.05) == (eq.bound_reached < bound)


def test_equivalence_refuses_what_it_cannot_test():
    for bad in (0.0, -1.0, math.inf, math.nan, True, "1"):
        with pytest.raises(StatsError, match="bound must be a finite number > 0"):
            equivalence_ttests(ONE, "y", "cond", "subj", bad)
    assert len(equivalence_ttests(ONE, "y", "cond", "subj", np.float32(1.0))) == 6
    with pytest.raises(StatsError, match=r"no such pair of 'cond' levels: \('c0', 'c9'\)"):
        equivalence_ttests(ONE, "y", "cond", "subj", 1.0, pairs=[("c0", "c9")])
    same = ONE.copy()
    same.loc[same["cond"] == "c3", "y"] = same.loc[same["cond"] == "c0", "y"].to_numpy() - 1
    eq = equivalence_ttests(same, "y", "cond", "subj", 2.0, pairs=[("c0", "c3"), ("c0", "c1")])
    assert list(eq["B"]) == ["c1"]  # a constant difference has no test: said in words
    assert ("c0", "c3", "difference 1 for every subject") in eq.attrs["constant_pairs"]


@pytest.mark.parametrize("ours, theirs", [("bonf", "bonferroni"), ("holm", "holm"),
                                          ("fdr_bh", "fdr_bh")])
def test_p_adjust_matches_statsmodels(ours, theirs):
    p = np.random.default_rng(0).uniform(0, 0.2, 55)
    np.testing.assert_allclose(p_adjust(p, ours), multipletests(p, method=theirs)[1])
    assert list(p_adjust(p, "none")) == list(p)
    with pytest.raises(StatsError, match="padjust"):
        p_adjust(p, "sidak")


def test_zscores_and_the_zero_variance_case():
    df = pd.DataFrame({"s": ["a"] * 4 + ["b"] * 4, "r": [1, 2, 3, 4, 5, 5, 5, 5]})
    z = zscore_by_subject(df, "r", "s")
    # subject a: mean 2.5, population SD √1.25
    assert list(z[:4]) == pytest.approx([(x - 2.5) / math.sqrt(1.25) for x in (1, 2, 3, 4)])
    assert list(z[4:]) == [0.0] * 4  # the stated case: no preference, not NaN


def _degenerate():
    base = [{"s": s, "c": c, "y": v} for s, row in zip("ABCD", [[1, 2, 3], [2, 3, 5], [3, 3, 3],
                                                                 [1, 2, 4]], strict=True)
            for c, v in zip("xyz", row, strict=True)]
    return pd.DataFrame(base)


@pytest.mark.parametrize("case, mutate, check", [
    ("missing cells", lambda d: d.drop(index=[11]), "missing_cells"),
    ("NaN", lambda d: d.assign(y=d["y"].where(d.index != 0, np.nan)), "nan"),
    ("zero variance", lambda d: d, "zero_variance"),
    ("constant differences", lambda d: d[d["s"] != "C"].assign(
        y=lambda x: x["y"].where(x["c"] != "z", x["y"] + 1)), "constant_differences"),
    ("n < 2", lambda d: d[d["s"] == "A"], "too_few_subjects"),
    ("duplicate rows", lambda d: pd.concat([d, d.iloc[[0]]]), "duplicate_rows"),
    ("mixed scales", lambda d: d.assign(scale=np.where(d["s"] == "A", "1-10", "1-7")),
     "mixed_scales"),
])
def test_preflight_reports_every_degenerate_case(case, mutate, check):
    d = mutate(_degenerate())
    rep = preflight(d, "y", "c", "s", scale="scale" if "scale" in d else None)
    assert check in set(rep["check"]), rep
    row = rep[rep["check"] == check].iloc[0]
    assert row["policy"] and row["detail"]


def test_degenerate_inputs_are_named_not_nan():
    d = _degenerate()
    with pytest.raises(StatsError, match="at least 2 subjects"):
        rm_anova(d[d["s"] == "A"], "y", "c", "s")
    with pytest.raises(StatsError, match="columns not in the data"):
        rm_anova(d, "rating", "c", "s")
    with pytest.raises(StatsError, match="single level"):
        rm_anova(d[d["c"] == "x"], "y", "c", "s")
    # missing cells: the subject is excluded from the ANOVA, not silently imputed
    a = rm_anova(d.drop(index=[11]), "y", "c", "s")
    assert a.iloc[0]["DF_err"] == (3 - 1) * (3 - 1)  # 3 complete subjects remain
    # constant differences: left out of the table and listed, never NaN or inf
    const = d[d["s"] != "C"].copy()
    const.loc[const["c"] == "z", "y"] = const.loc[const["c"] == "y", "y"].to_numpy() + 1
    pw = pairwise_ttests(const, "y", "c", "s")
    assert ("y", "z", "difference -1 for every subject") in pw.attrs["constant_pairs"]
    assert np.isfinite(pw.select_dtypes("number").to_numpy()).all()


def test_published_identification_counts():
    """Table 3: 14 subjects × 3 answers; 35/42 correct, third attempt 12/14, experts 16/18,
    novices 19/24."""
    rows = []
    wrong = {("E0", 1), ("E1", 3), ("N0", 1), ("N1", 1), ("N2", 2), ("N3", 2), ("N4", 3)}
    for g, n in (("expert", 6), ("novice", 8)):
        for i in range(n):
            s = f"{g[0].upper()}{i}"
            for rep in (1, 2, 3):
                rows.append({"s": s, "rep": rep, "group": g, "ok": int((s, rep) not in wrong)})
    t = identification_scores(pd.DataFrame(rows), "s", "ok", "rep", "group")["summary"]
    t = t.set_index("scope")
    assert round(t.loc["all", "percent"], 1) == 83.3
    assert round(t.loc["last repetition", "percent"], 1) == 85.7
    assert round(t.loc["group expert", "percent"], 1) == 88.9
    assert round(t.loc["group novice", "percent"], 1) == 79.2
    # exact binomial against chance 1/6: scipy.stats.binomtest(35, 42, 1/6, "greater")
    assert t.loc["all", "p_binom"] == pytest.approx(
        stats.binomtest(35, 42, 1 / 6, alternative="greater").pvalue)
    assert t.loc["all", "p_binom"] < 1e-15
    assert t.loc["all", "chance_percent"] == pytest.approx(100 / 6)


def test_confusion_matrix():
    df = pd.DataFrame({"s": ["a", "b"], "ok": [1, 0],
                       "answer": ["wood,rubber,aluminum", "rubber,wood,aluminum"],
                       "truth": ["wood,rubber,aluminum", "wood,rubber,aluminum"]})
    c = identification_scores(df, "s", "ok", answer="answer", truth="truth")["confusion"]
    assert c.loc["wood", "rubber"] == 1 and c.loc["rubber", "wood"] == 1
    assert c.loc["aluminum", "aluminum"] == 2 and int(c.to_numpy().sum()) == 6


def test_bad_correct_column():
    with pytest.raises(StatsError, match="0 or 1"):
        identification_scores(pd.DataFrame({"s": ["a"], "ok": [2]}), "s", "ok")


def test_mauchly_is_not_reported_when_it_is_undefined():
    """3 subjects, 4 levels: the 3 contrasts' covariance has rank ≤ 2, so det = 0 and
    Mauchly's χ² is infinite — a test that cannot be run, not a violation (p = 0)."""
    d = pd.DataFrame([{"s": s, "c": c, "y": float(v)} for s, row in
                      enumerate([[1, 3, 2, 5], [2, 2, 4, 6], [1, 4, 4, 4]])
                      for c, v in zip("abcd", row, strict=True)])
    a = rm_anova(d, "y", "c", "s")
    assert "W_mauchly" not in a and "p_spher" not in a
    assert "Mauchly" in a.attrs["notes"][0] and "3 subjects" in a.attrs["notes"][0]
    # ε_GG is still defined and bounded by 1/(k − 1) ≤ ε ≤ 1
    assert 1 / 3 <= a.loc[0, "eps_gg"] <= 1 and np.isfinite(a.loc[0, "p_gg"])



def test_factorial_main_effects_match_a_hand_computation():
    """Each parameter's preferred level: per participant, the mean z (population SD, as the
    study) over the four sets at a level; then over participants. For a 2-level factor the
    ANOVA's p equals the paired t-test on those per-participant means (scipy ttest_rel)."""
    import itertools

    from analysis.study import rating_factorial

    rng = np.random.default_rng(3)
    rows = []
    for s in range(6):
        for f, d, a in itertools.product(("low", "high"), repeat=3):
            r = 5 + 2 * (f == "high") - 1 * (a == "high") + rng.integers(-1, 2) + s % 2
            rows.append({"participant": f"P{s}", "protocol": "factorial", "valid": True,
                         "phase": "rating", "block": "wood", "sample": f"wood-{f}{d}{a}",
                         "frequency": f, "decay": d, "slope": a, "rating": float(r)})
    data = pd.DataFrame(rows)
    eff = rating_factorial(data, ["frequency", "decay", "slope"], by="block")["wood"][
        "main_effects"].set_index("factor")
    # by hand with numpy
    z = data.groupby("participant")["rating"].transform(lambda x: (x - x.mean()) / x.std(ddof=0))
    for factor in ("frequency", "decay", "slope"):
        per = data.assign(z=z).groupby(["participant", factor])["z"].mean().unstack()
        assert eff.loc[factor, "mean_z_high"] == pytest.approx(per["high"].mean())
        assert eff.loc[factor, "difference"] == pytest.approx((per["high"] - per["low"]).mean())
        assert eff.loc[factor, "p_unc"] == pytest.approx(
            stats.ttest_rel(per["high"], per["low"]).pvalue, rel=1e-6)
    assert eff.loc["frequency", "preferred"] == "high" and eff.loc["slope", "preferred"] == "low"
