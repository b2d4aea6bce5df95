"""Statistics at their edges (issue 15): every case below gave a wrong number before.

Independent implementation: pingouin 0.7.0 (``pingouin.rm_anova``,
``pingouin.pairwise_tests``), where both are defined; hand arithmetic otherwise, noted
beside the number.
"""

import math

import numpy as np
import pandas as pd
import pingouin as pg
import pytest
from hypothesis import assume, example, given
from hypothesis import strategies as st

import analysis as A
from analysis.stats import StatsError


def _long(matrix, levels=None, reps=1):
    """Subjects × levels cell values as long rows (each repeated ``reps`` times)."""
    m = np.asarray(matrix, float)
    levels = levels or [f"s{j}" for j in range(m.shape[1])]
    return pd.DataFrame([(f"P{i:02d}", levels[j], m[i, j]) for i in range(m.shape[0])
                         for j in range(m.shape[1]) for _ in range(reps)],
                        columns=["participant", "sample", "rating"])


def _thirds():
    """Integer ratings averaged over 3 repetitions: x − y is exactly 1 for everyone, but
    7/3 − 4/3 = 0.9999999999999998 in binary."""
    rows = []
    for i, (x, y) in enumerate([((3, 2, 2), (2, 1, 1)), ((4, 3, 3), (3, 2, 2)),
                                ((2, 3, 2), (1, 2, 1)), ((5, 4, 5), (4, 3, 4))]):
        rows += [(f"P{i}", "x", v) for v in x] + [(f"P{i}", "y", v) for v in y]
        rows += [(f"P{i}", "z", v) for v in (1, 7, 4 + i)]
    return pd.DataFrame(rows, columns=["participant", "sample", "rating"])


def test_a_constant_difference_in_floating_point_is_not_a_huge_effect():
    d = _thirds()
    pw = A.pairwise_ttests(d, "rating", "sample", "participant")
    assert ("x", "y") not in set(zip(pw["A"], pw["B"], strict=True))  # was t = 4.5e15
    (a, b, why), = [c for c in pw.attrs["constant_pairs"] if {c[0], c[1]} == {"x", "y"}]
    assert why == "difference 1 for every subject"  # 7/3 − 4/3 reads 1, as by hand
    assert np.isfinite(pw[["t", "dz", "p_unc"]].to_numpy()).all()
    assert (pw["dz"].abs() < 100).all()
    pre = A.preflight(d, "rating", "sample", "participant")
    assert "constant_differences" in set(pre["check"])


def test_an_exact_zero_difference_is_shown_as_zero():
    # x and y differ by +1 for two subjects and −1 for two: the mean difference is 0 by
    # hand; floating-point averaging of thirds leaves ~1e-16
    m = np.array([[7, 4, 1], [4, 7, 2], [7, 4, 3], [4, 7, 5]], float) / 3
    pw = A.pairwise_ttests(_long(m), "rating", "sample", "participant")
    row = pw[(pw["A"] == "s0") & (pw["B"] == "s1")].iloc[0]
    assert row["mean_diff"] == 0.0 and row["t"] == 0.0 and row["p_unc"] == 1.0


def test_identical_ratings_leave_the_anova_undefined_in_words():
    d = _long(np.full((5, 3), 4.0))
    with pytest.raises(StatsError, match="no variation"):
        A.rm_anova(d, "rating", "sample", "participant")


def test_two_participants_three_levels_give_numbers_or_a_note():
    rng = np.random.default_rng(3)
    for _ in range(50):
        d = _long(rng.integers(1, 8, (2, 3)))
        try:
            aov = A.rm_anova(d, "rating", "sample", "participant")
        except StatsError as exc:
            assert "no variation" in str(exc) or "no error variance" in str(exc)
            continue
        assert np.isfinite(aov.select_dtypes("number").to_numpy()).all()
        assert "p_spher" not in aov  # 2 subjects, 2 contrasts: singular, said in a note
        assert any("Mauchly" in n for n in aov.attrs["notes"])


def test_an_infinite_rating_is_refused_naming_column_and_row():
    d = _long(np.arange(12.0).reshape(4, 3))
    d.loc[5, "rating"] = np.inf
    for fn in (lambda: A.rm_anova(d, "rating", "sample", "participant"),
               lambda: A.pairwise_ttests(d, "rating", "sample", "participant"),
               lambda: A.zscore_by_subject(d, "rating", "participant")):
        with pytest.raises(StatsError, match=r"column 'rating' is not finite in rows 5"):
            fn()


@pytest.mark.parametrize("column", ["participant", "sample"])
def test_a_missing_label_is_refused_naming_column_and_row(column):
    d = _long(np.arange(12.0).reshape(4, 3))
    d.loc[[2, 7], column] = None
    with pytest.raises(StatsError, match=rf"column '{column}' has no label in rows 2, 7"):
        A.rm_anova(d, "rating", "sample", "participant")


@pytest.mark.parametrize("scale", [1e-150, 1e150])
def test_mauchly_and_epsilons_do_not_depend_on_the_units(scale):
    rng = np.random.default_rng(5)
    m = rng.normal(4, 1, (8, 4))
    ref = A.rm_anova(_long(m), "rating", "sample", "participant").iloc[0]
    got = A.rm_anova(_long(m * scale), "rating", "sample", "participant").iloc[0]
    for col in ("F", "p_unc", "np2", "eps_gg", "eps_hf", "W_mauchly", "p_spher"):
        assert math.isfinite(got[col]), col
        assert got[col] == pytest.approx(ref[col], rel=1e-9), col
    assert got["SS"] == pytest.approx(ref["SS"] * scale ** 2, rel=1e-9)


def test_listwise_by_default_and_pairwise_on_request():
    rng = np.random.default_rng(8)
    d = _long(rng.normal(4, 1, (6, 3)))
    d = d[~((d["participant"] == "P02") & (d["sample"] == "s2"))]
    lw = A.pairwise_ttests(d, "rating", "sample", "participant")
    assert (lw["n"] == 5).all() and lw.attrs["excluded_subjects"] == ["P02"]
    pw = A.pairwise_ttests(d, "rating", "sample", "participant", missing="pairwise")
    assert pw.set_index(["A", "B"]).loc[("s0", "s1"), "n"] == 6
    assert pw.attrs["excluded_subjects"] == []
    # the ANOVA uses the same participants as the default t-tests
    assert A.rm_anova(d, "rating", "sample", "participant")["n"].iloc[0] == 5
    # pingouin (listwise by default) agrees on the default
    ref = pg.pairwise_tests(d, dv="rating", within="sample", subject="participant",
                            padjust="holm")
    assert lw["t"].to_numpy() == pytest.approx(ref["T"].to_numpy(), rel=1e-9)
    assert lw["p_corr"].to_numpy() == pytest.approx(ref["p_corr"].to_numpy(), rel=1e-9)
    with pytest.raises(StatsError, match="missing must be one of"):
        A.pairwise_ttests(d, "rating", "sample", "participant", missing="some")


def test_sphericity_of_a_three_level_factor_in_a_two_factor_design():
    """pingouin.rm_anova on two within factors gives ε_GG, Mauchly's W and its p per
    effect (before, only a single factor got any sphericity correction); ours agree."""
    rng = np.random.default_rng(11)
    rows = [(f"P{i}", a, b, rng.normal(0, 1) + (a == "a2") + 0.5 * (b == "b1") * i / 9)
            for i in range(10) for a in ("a0", "a1", "a2") for b in ("b0", "b1")]
    d = pd.DataFrame(rows, columns=["participant", "A", "B", "y"])
    ours = A.rm_anova(d, "y", ["A", "B"], "participant").set_index("Source")
    ref = pg.rm_anova(d, dv="y", within=["A", "B"], subject="participant",
                      effsize="np2").set_index("Source")
    for src, theirs in (("A", "A"), ("A * B", "A * B")):
        assert ours.loc[src, "F"] == pytest.approx(ref.loc[theirs, "F"], rel=1e-9)
        assert ours.loc[src, "eps_gg"] == pytest.approx(ref.loc[theirs, "eps"], rel=1e-9)
        assert ours.loc[src, "p_gg"] == pytest.approx(ref.loc[theirs, "p_GG_corr"], rel=1e-9)
        assert ours.loc[src, "W_mauchly"] == pytest.approx(ref.loc[theirs, "W_spher"], rel=1e-9)
        assert ours.loc[src, "p_spher"] == pytest.approx(ref.loc[theirs, "p_spher"], rel=1e-6)
        assert "p_hf" in ours.columns and math.isfinite(ours.loc[src, "p_hf"])
    assert "eps_gg" not in ours.columns or math.isnan(ours.loc["B", "eps_gg"])  # 2 levels


# ---------------------------------------------------------------- property-based
#: powers of ten of the data's units; half the examples in plain units (pingouin compared)
exponents = st.one_of(st.just(0), st.integers(-150, 150))
designs = st.tuples(st.integers(2, 40), st.integers(2, 12), st.integers(1, 3), exponents,
                    st.integers(0, 2 ** 32 - 1),
                    st.sampled_from(["random", "ties", "constant_column", "missing"]))


@given(designs)
def test_one_factor_numbers_are_finite_or_a_named_error_and_agree_with_pingouin(design):
    n, k, reps, exp10, seed, kind = design
    rng = np.random.default_rng(seed)
    m = rng.integers(1, 8, (n, k, reps)).mean(axis=2)
    if kind == "ties":
        m[:, 1] = m[:, 0]
    elif kind == "constant_column":
        m[:, -1] = 4.0
    d = _long(m * 10.0 ** exp10)
    if kind == "missing":
        d = d.drop(index=rng.choice(d.index, size=max(1, len(d) // 10), replace=False))
    for fn in (A.rm_anova, A.pairwise_ttests):
        try:
            out = fn(d, "rating", "sample", "participant")
        except StatsError as exc:
            assert str(exc)
            continue
        assert np.isfinite(out.select_dtypes("number").to_numpy()).all()
        if fn is A.pairwise_ttests:
            assert (out["dz"].abs() < 1e6).all()  # a constant pair is listed, not tested
        if exp10 == 0 and fn is A.rm_anova and kind != "missing":
            try:  # pingouin 0.7.0 divides by zero in its sphericity test at n = 2
                ref = pg.rm_anova(d, dv="rating", within="sample", subject="participant",
                                  detailed=True, effsize="np2")
            except ZeroDivisionError:
                continue
            assume(np.isfinite(ref.loc[0, "F"]))
            assert out.loc[0, "F"] == pytest.approx(ref.loc[0, "F"], rel=1e-6)
            assert out.loc[0, "p_unc"] == pytest.approx(ref.loc[0, "p_unc"], rel=1e-6,
                                                        abs=1e-300)


@given(st.integers(2, 12), st.integers(2, 4), st.integers(2, 3), exponents,
       st.integers(0, 2 ** 32 - 1))
def test_factorial_numbers_are_finite_or_a_named_error(n, ka, kb, exp10, seed):
    rng = np.random.default_rng(seed)
    rows = [(f"P{i}", f"a{a}", f"b{b}", float(rng.integers(1, 8)) * 10.0 ** exp10)
            for i in range(n) for a in range(ka) for b in range(kb)]
    d = pd.DataFrame(rows, columns=["participant", "A", "B", "y"])
    try:
        out = A.rm_anova(d, "y", ["A", "B"], "participant")
    except StatsError as exc:
        assert str(exc)
        return
    assert np.isfinite(out.drop(columns="Source").to_numpy(float)[
        ~np.isnan(out.drop(columns="Source").to_numpy(float))]).all()
    if exp10 == 0:
        try:  # pingouin 0.7.0 divides by zero in its sphericity test at n = 2
            ref = pg.rm_anova(d, dv="y", within=["A", "B"], subject="participant",
                              effsize="np2")
        except ZeroDivisionError:
            return
        for src in ("A", "B", "A * B"):
            f_ref = float(ref.set_index("Source").loc[src, "F"])
            if np.isfinite(f_ref):
                assert float(out.set_index("Source").loc[src, "F"]) == pytest.approx(
                    f_ref, rel=1e-6)


# ---------------------------------------------------------------- companions
def test_friedman_agrees_with_pingouin():
    """pingouin.friedman (Q, W, p) on the committed example, which has ties. (Its Wilcoxon
    tests are not a reference: scipy ranks the floating-point noise of tied cell means;
    tests/analysis/test_against_r.py compares ours with R's.)"""
    df = A.datasets.read_dataset("ratings")
    ours = A.friedman(df, "rating", "sample", "participant").iloc[0]
    ref = pg.friedman(df, dv="rating", within="sample", subject="participant").iloc[0]
    for a, b in (("Q", "Q"), ("W", "W"), ("p_unc", "p_unc")):
        assert ours[a] == pytest.approx(ref[b], rel=1e-9), a


def test_signed_ranks_see_ties_between_equal_fractions():
    """7/3 − 2 and 2 − 5/3 are the same difference (1/3) but different doubles. R with
    ties made visible: ``d <- c(7/3-2, -(2-5/3), 1, 4/3-1, 2/3, 5/3-1, 1/3, -2/3);
    wilcox.test(d, digits.rank = 7)`` gives V = 27.5, p = 0.19968592093575846 (plain
    ``wilcox.test(d)`` ranks the noise: V = 29, p = 0.1405)."""
    from analysis.stats import signed_rank_test

    d = np.array([7 / 3 - 2, -(2 - 5 / 3), 1, 4 / 3 - 1, 2 / 3, 5 / 3 - 1, 1 / 3, -2 / 3])
    r = signed_rank_test(d, tol=1e-9)
    assert r["V"] == 27.5 and r["method"] == "normal" and r["ties"]
    assert r["p"] == pytest.approx(0.19968592093575846, rel=1e-12)


def test_friedman_of_identical_ratings_is_undefined_in_words():
    with pytest.raises(StatsError, match="Friedman test is undefined"):
        A.friedman(_long(np.full((5, 4), 3.0)), "rating", "sample", "participant")


def test_dz_interval_covers_at_its_level():
    """Coverage of the noncentral-t interval over 2000 simulated studies of n = 12 with a
    true d_z of 0.5 (normal differences): 95 % ± 1.5 % (Monte-Carlo SE 0.5 %)."""
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(2000):
        d = rng.normal(0.5, 1.0, 12)
        lo, hi = A.dz_ci(d.mean() / d.std(ddof=1), 12)
        hits += lo <= 0.5 <= hi
    assert hits / 2000 == pytest.approx(0.95, abs=0.015)
    lo, hi = A.dz_ci(16.17, 3)  # far in the tails scipy's noncentral t returns NaN
    assert 0 < lo < 16.17 < hi and math.isfinite(hi)


def test_identification_with_each_participant_as_the_unit():
    """Table 3's 35 of 42 answers, spread as 9 people 3 of 3, 4 people 2 of 3 and one 0 of
    3: with people as the unit, 13 of 14 are above chance (1/6) and one below, so the sign
    test's p is P(X ≥ 13 | 14, ½) = 15 / 2¹⁴ by hand."""
    correct = [1, 1, 1] * 9 + [1, 1, 0] * 4 + [0, 0, 0]  # 27 + 8 + 0 = 35 of 42
    d = pd.DataFrame({"participant": [f"S{i // 3}" for i in range(42)], "correct": correct})
    res = A.participant_identification_test(d, "participant", "correct").iloc[0]
    assert res["n"] == 14 and res["above"] == 13
    assert res["p_sign"] == pytest.approx(15 / 2 ** 14, rel=1e-12)
    assert res["mean_percent"] == pytest.approx(100 * 35 / 42)
    assert 0 < res["p_t"] < 1e-5


def test_trial_level_models_keep_participants_with_missing_cells():
    """The mixed model's Wald χ² equals statsmodels' own wald_test_terms on the unscaled
    data (174.2 on the example; ours fits centred, scaled ratings); both models keep the
    participant who lacks a cell, which the ANOVA drops; the ordinal mixed model's LR is
    ≥ 0 and does not change when the samples are renamed."""
    import statsmodels.formula.api as smf

    from analysis.ordinal import ordinal_mixed
    from analysis.stats import mixed_oneway

    df = A.datasets.read_dataset("ratings")
    ours = mixed_oneway(df, "rating", "sample", "participant").iloc[0]
    ref = smf.mixedlm("rating ~ C(sample, Sum)", df, groups=df["participant"]).fit(reml=True)
    assert ours["chi2"] == pytest.approx(float(ref.wald_test_terms().table.loc[
        "C(sample, Sum)", "statistic"]), rel=1e-3)
    gap = df[~((df["participant"] == df["participant"].iloc[0]) & (df["sample"] == "wood"))]
    assert A.rm_anova(gap, "rating", "sample", "participant")["n"].iloc[0] == 5
    assert mixed_oneway(gap, "rating", "sample", "participant")["n_subjects"].iloc[0] == 6
    o = ordinal_mixed(gap, "rating", "sample", "participant").iloc[0]
    assert o["n_subjects"] == 6 and o["lr"] >= 0 and o["converged"]
    renamed = gap.assign(sample=gap["sample"].map(lambda s: f"z_{s}"))
    assert ordinal_mixed(renamed, "rating", "sample", "participant")["lr"].iloc[0] == \
        pytest.approx(o["lr"], rel=1e-4)
    with pytest.raises(StatsError, match="at least 3 distinct values"):
        ordinal_mixed(_long(np.tile([1.0, 2.0], (4, 2))), "rating", "sample", "participant")


def test_factorial_z_scores_per_material_as_the_paper():
    """normalize = "zscore_block": each participant's ratings of one block's sets have mean
    0 and SD 1 (the reality-based models normalised per subject and material); "zscore"
    pools the blocks, so a participant who rates one material higher overall shifts it."""
    from analysis.study import rating_factorial

    rng = np.random.default_rng(2)
    rows = []
    for i in range(6):
        for block, shift in (("rubber", 0.0), ("wood", 3.0)):
            for f in ("low", "high"):
                for g in ("low", "high"):
                    rows.append({"participant": f"P{i}", "block": block,
                                 "sample": f"{block}-{f}{g}", "f": f, "g": g, "valid": True,
                                 "rating": float(rng.integers(1, 6)) + shift})
    d = pd.DataFrame(rows)
    per_block = rating_factorial(d, ["f", "g"], by="block", normalize="zscore_block")
    pooled = rating_factorial(d, ["f", "g"], by="block", normalize="zscore")
    # per block, a subject's z-scores average 0 over the block's sets: the set means do too
    for res in per_block.values():
        assert res["sets"]["mean"].mean() == pytest.approx(0.0, abs=1e-12)
    assert pooled["wood"]["sets"]["mean"].mean() > 0.5  # wood rated higher overall
    # the set means against z computed by pandas directly (population SD per subject×block)
    g = d.groupby(["participant", "block"])["rating"]
    z = (d["rating"] - g.transform("mean")) / g.transform(lambda x: x.std(ddof=0))
    ref = z.groupby(d["sample"]).mean()
    got = pd.concat([r["sets"] for r in per_block.values()]).set_index("sample")["mean"]
    assert got.sort_index().to_numpy() == pytest.approx(ref.sort_index().to_numpy(), abs=1e-12)


def test_simple_effects_follow_a_significant_interaction():
    """A matters only at B = b1: the interaction is significant, and the simple effect of
    A at each level of B is the paired t² of scipy.stats.ttest_rel on that level's cells."""
    from scipy import stats as sst

    from analysis.study import simple_effects

    rng = np.random.default_rng(4)
    rows = [(f"P{i}", a, b, rng.normal(0, 0.3) + (2.0 if (a, b) == ("a1", "b1") else 0.0))
            for i in range(10) for a in ("a0", "a1") for b in ("b0", "b1")]
    d = pd.DataFrame(rows, columns=["participant", "A", "B", "y"])
    aov = A.rm_anova(d, "y", ["A", "B"], "participant")
    se = simple_effects(d, "y", ["A", "B"], "participant", aov)
    assert set(se["at"]) == {"B=b0", "B=b1", "A=a0", "A=a1"}
    for level in ("b0", "b1"):
        sub = d[d["B"] == level].pivot(index="participant", columns="A", values="y")
        t = sst.ttest_rel(sub["a1"], sub["a0"]).statistic
        row = se[(se["effect"] == "A") & (se["at"] == f"B={level}")].iloc[0]
        assert row["F"] == pytest.approx(t ** 2, rel=1e-9)
    assert se.set_index("at").loc["B=b1", "p_holm"] < 0.001
    assert (se["p_holm"] >= se["p_unc"]).all()


def test_experts_and_novices_compared_with_each_person_as_one_observation():
    """Proportions correct of 3 experts (1, 1, 2/3) and 4 novices (2/3, 1/3, 1/3, 0):
    scipy.stats.mannwhitneyu on those seven numbers gives the same U and p."""
    from scipy import stats as sst

    per = {"E1": [1, 1, 1], "E2": [1, 1, 1], "E3": [1, 1, 0], "N1": [1, 1, 0],
           "N2": [1, 0, 0], "N3": [0, 1, 0], "N4": [0, 0, 0]}
    d = pd.DataFrame([(p, "expert" if p[0] == "E" else "novice", c)
                      for p, cs in per.items() for c in cs],
                     columns=["participant", "group", "correct"])
    res = A.participant_identification_test(d, "participant", "correct", group="group")
    g = res.attrs["groups"]
    ref = sst.mannwhitneyu([1, 1, 2 / 3], [2 / 3, 1 / 3, 1 / 3, 0], alternative="two-sided")
    assert (g["group_a"], g["n_a"], g["n_b"]) == ("expert", 3, 4)
    assert g["U"] == ref.statistic and g["p_mwu"] == pytest.approx(ref.pvalue, rel=1e-12)
    assert g["mean_percent_a"] == pytest.approx(100 * 8 / 9)


@given(st.floats(0.0, 60.0), st.integers(1, 6), st.integers(2, 80))
def test_partial_eta_squared_interval_brackets_the_estimate_and_matches_p(F, df1, df2):
    """The noncentral-F interval is ordered within [0, 1) and its lower bound leaves 0
    exactly when the central F test's p (scipy.stats.f.sf) is below α/2: the inversion's
    duality with the F test."""
    lo, hi = A.np2_ci(F, df1, df2)
    p = float(__import__("scipy").stats.f.sf(F, df1, df2))
    assert 0.0 <= lo <= hi < 1.0
    assume(abs(p - 0.025) > 1e-6)
    assert (lo > 0) == (p < 0.025)


def test_a_between_subject_group_in_the_mixed_model():
    """Experts rate 1 point higher everywhere: the group row of sample × group is
    significant and the interaction is not; statsmodels' own wald_test_terms on the
    unscaled formula with sum-to-zero contrasts gives the same type-III χ² (the reference
    beside the number; its optimiser stops ~3e-4 from the REML optimum, hence 1e-3)."""
    import statsmodels.formula.api as smf

    from analysis.stats import mixed_oneway

    rng = np.random.default_rng(6)
    rows = [(f"P{i}", "expert" if i < 8 else "novice", s,
             3 + j + (1.0 if i < 8 else 0.0) + rng.normal(0, 0.3) + 0.2 * (i % 4))
            for i in range(16) for j, s in enumerate(("a", "b", "c")) for _ in range(2)]
    d = pd.DataFrame(rows, columns=["participant", "group", "sample", "rating"])
    res = mixed_oneway(d, "rating", "sample", "participant", between="group")
    res = res.set_index("Source")
    assert res.loc["group", "p_unc"] < 0.01 and res.loc["sample * group", "p_unc"] > 0.01
    ref = smf.mixedlm("rating ~ C(sample, Sum) * C(group, Sum)", d,
                      groups=d["participant"]).fit(reml=True).wald_test_terms().table
    assert res.loc["group", "chi2"] == pytest.approx(
        float(ref.loc["C(group, Sum)", "statistic"]), rel=1e-3)


@given(st.integers(2, 12), st.integers(0, 2 ** 32 - 1), st.floats(0.0, 1.0))
@example(12, 3515, 0.875)  # CI found it: 32 letters, the 27th written "aa", which reads as a
def test_letters_never_join_a_significant_pair(k, seed, share):
    """Any pattern of significant pairs: two levels share a letter exactly when their pair
    is not significant (Piepho's insert-absorb-sweep), and every level gets a letter; the
    old groups chained non-significant pairs and held pairs with Holm p = .001. Each letter
    is one character, and no level carries a letter the others make redundant."""
    import itertools

    from analysis.study import LETTERS, compact_letters, letter_groups

    rng = np.random.default_rng(seed)
    levels = [f"s{i}" for i in range(k)]
    pairs = list(itertools.combinations(levels, 2))
    p = np.where(rng.random(len(pairs)) < share, 0.2, 0.01)
    pw = pd.DataFrame({"A": [a for a, _ in pairs], "B": [b for _, b in pairs], "p_corr": p})
    letters = compact_letters(levels, pw)
    assert all(letters[lv] for lv in levels)
    for (a, b), pv in zip(pairs, p, strict=True):
        shared = bool(set(letters[a]) & set(letters[b]))
        assert shared == (pv >= 0.05), (a, b, pv, letters)
    groups = letter_groups(levels, pw)
    assert [[lv for lv in levels if ch in letters[lv]] for ch in LETTERS[:len(groups)]] == groups
    for g in groups:  # swept: each level in a letter needs it, for a pair or for itself
        for x in g:
            others = [h for h in groups if h is not g and x in h]
            assert not others or any(not any(y in h for h in others) for y in g if y != x)


def test_letters_of_a_chain_by_hand():
    """a–b, b–c, c–d not significant, every other pair significant: three letters, each
    joining one non-significant pair (worked by hand)."""
    from analysis.study import compact_letters

    pw = pd.DataFrame({"A": list("aaabbc"), "B": list("bcdcdd"),
                       "p_corr": [0.3, 0.01, 0.01, 0.3, 0.01, 0.3]})
    assert compact_letters(list("abcd"), pw) == {"a": "a", "b": "ab", "c": "bc", "d": "c"}
