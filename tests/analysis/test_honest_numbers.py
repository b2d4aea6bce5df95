"""Numbers that say what is true at the edges: p on the right side of α, bounds instead of
an underflowed 0, statistics that do not move when every rating is shifted or scaled,
files that cannot hang the loader."""

from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import analysis as A
from analysis.report import _p_bounds
from analysis.report_text import p_digits as _p_digits
from analysis.report_text import p_text as _p
from analysis.session_format import TrialsFileError, read_trials
from analysis.stats import mixed_oneway


@pytest.mark.parametrize("p, text", [
    (0.0496, "p = .0496"),   # rounds to .050 at 3 decimals: one more shows the side
    (0.0537, "p = .054"),    # not ".05"
    (0.045, "p = .045"),
    (0.05, "p = .050"),
    (0.0499999, "p = .0499999"),
    (0.12, "p = .12"),
    (0.0004, "p < .001"),
    (0.0, "p < .001")])
def test_a_p_value_shows_which_side_of_alpha_it_lies(p, text):
    assert _p(p) == text
    assert (float("0" + _p_digits(p)) < 0.05) == (p < 0.05) or p < 0.001


def test_an_underflowed_p_is_a_bound_in_report_json():
    rep = {"mixed": [{"chi2": 2000.0, "p_unc": 0.0}, {"chi2": 3.0, "p_unc": 0.08}],
           "anova": {"p": 1e-320, "F": 0.0}}
    out = _p_bounds(rep)
    assert out["mixed"][0]["p_unc"] == "< 2.3e-308" and out["mixed"][1]["p_unc"] == 0.08
    assert out["anova"] == {"p": "< 2.3e-308", "F": 0.0}  # only p-values become bounds


def test_a_fifo_for_trials_tsv_is_refused_by_name(tmp_path):
    fifo = tmp_path / "trials.tsv"
    os.mkfifo(fifo)
    with pytest.raises(TrialsFileError, match="trials.tsv: not a regular file .a named pipe"):
        read_trials(fifo)  # before: blocked for ever waiting for a writer


def _study(seed: int, n: int = 8, k: int = 4, reps: int = 3) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = [(f"P{p}", f"s{s}", int(rng.integers(1, 8)))
            for p in range(n) for s in range(k) for _ in range(reps)]
    return pd.DataFrame(rows, columns=["participant", "sample", "rating"])


def _stats(d: pd.DataFrame) -> dict[str, np.ndarray]:
    args = (d, "rating", "sample", "participant")
    out = {}
    pw = A.pairwise_ttests(*args)
    out["t"], out["p_t"] = pw["t"].to_numpy(), pw["p_unc"].to_numpy()
    try:
        wx = A.pairwise_wilcoxon(*args)
        out["V"], out["p_w"] = wx["V"].to_numpy(), wx["p_unc"].to_numpy()
        out["Q"] = A.friedman(*args)["Q"].to_numpy()
    except A.StatsError:
        pass
    aov = A.rm_anova(*args)
    out["F"], out["eps"] = aov["F"].to_numpy(), aov["eps_gg"].to_numpy()
    mx = mixed_oneway(*args)
    out["chi2"] = mx["chi2"].to_numpy()
    out["z"] = A.zscore_by_subject(d, "rating", "participant").to_numpy()
    return out


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1),
       shift=st.sampled_from([1e12, -1e6, 3.0, 2.0 ** 40]),
       scale=st.sampled_from([1e-6, 7.0, 1e9, 0.1]))
def test_every_statistic_ignores_a_shift_and_a_scale_of_the_ratings(seed, shift, scale):
    """Ratings shifted by a constant (exactly, as integers are) or multiplied by a positive
    one give the same statistics, to 1e-9 (the REML fit: 1e-6, its search's precision).
    A shift of 1e12 once made every rating 'the same' (the tolerance followed the
    magnitude) and left 1e-4 of rounding in the cell means."""
    d = _study(seed)
    base = _stats(d)
    for moved in (d.assign(rating=d["rating"] + shift), d.assign(rating=d["rating"] * scale)):
        got = _stats(moved)
        assert got.keys() == base.keys()
        for key, ref in base.items():
            rel = 1e-6 if key == "chi2" else 1e-9
            np.testing.assert_allclose(got[key], ref, rtol=rel, atol=1e-12, err_msg=key)


def test_no_participant_variance_is_an_sd_of_zero():
    """Participants who agree exactly (no offsets): REML's optimum is on the boundary, and
    the SD is 0, as lme4 reports it (a singular fit), not 5e-08."""
    rng = np.random.default_rng(4)
    rows = [(f"P{p}", s, float(s == "b") + rng.normal(0, 1))
            for p in range(6) for s in "abc" for _ in range(4)]
    d = pd.DataFrame(rows, columns=["participant", "sample", "rating"])
    d["rating"] -= d.groupby("participant")["rating"].transform("mean")  # no offsets at all
    assert mixed_oneway(d, "rating", "sample", "participant")["sd_subject"].iloc[0] == 0.0


def test_the_p_matrix_shows_alpha_and_the_confusion_numbers_read(tmp_path):
    """p = .04 and .06 get different colours (bands at .001, .01, .05), and the confusion
    matrix's numbers are white on dark cells (they were black on navy)."""
    from matplotlib.colors import to_rgb
    from PIL import Image

    from analysis import plots

    pw = pd.DataFrame({"A": ["a", "a", "b"], "B": ["b", "c", "c"],
                       "p_holm": [0.04, 0.06, 0.0004]})
    a = {"id": "t/p", "result": {"samples": [{"sample": s} for s in "abc"], "pairwise": pw}}
    png = tmp_path / plots.rating_pmatrix(a, tmp_path)[0]
    img = np.asarray(Image.open(png).convert("RGB"), float) / 255
    colours = {tuple(np.round(c, 2)) for c in img.reshape(-1, 3)}
    for band in ("#6baed6", "#f0f0f0", "#08306b"):  # < .05, ≥ .05, < .001
        assert tuple(np.round(to_rgb(band), 2)) in colours, band
    c = pd.DataFrame([[9, 1], [2, 8]], index=["x", "y"], columns=["x", "y"])
    assert plots._ink(c.to_numpy()).tolist() == [["white", "black"], ["black", "white"]]
    assert (tmp_path / plots.confusion({"id": "t/c", "result": {"confusion": c}},
                                       tmp_path)[0]).exists()


def test_the_wilcoxon_floor_at_many_participants_is_zero_not_an_overflow():
    """2/2ⁿ for the smallest exact p overflowed (OverflowError) above ~1024 participants."""
    rng = np.random.default_rng(1)
    rows = [(f"P{p}", s, float(rng.integers(1, 8))) for p in range(1100) for s in "abc"]
    d = pd.DataFrame(rows, columns=["participant", "sample", "rating"])
    wx = A.pairwise_wilcoxon(d, "rating", "sample", "participant")
    assert wx.attrs["p_floor"] == 0.0 and (wx["method"] == "normal").all()


def test_the_summary_names_a_significant_interaction():
    """It mentioned only main effects while a significant interaction had its own table."""
    from analysis.report import _summary

    a = {"id": "f/r", "type": "factorial", "n_subjects": 10, "groups": {"wood": {
        "n_subjects": 10, "most_significant": "decay", "most_significant_p": 0.3,
        "best_set": {"sample": "wood-LHL"},
        "anova": [{"Source": "decay", "p_unc": 0.3},
                  {"Source": "frequency * slope", "p_unc": 0.012}]}}}
    text = _summary(a)
    assert "no main effect significant" in text
    assert "interaction frequency × slope (p = .012)" in text


def test_a_missing_first_rating_does_not_rename_participants():
    """Rows (P1, NaN), (P2, 5), (P1, 3): P1's data were labelled P2 once a rating was
    missing, so the wrong person was listed as excluded."""
    from analysis.stats import wide_means

    d = pd.DataFrame({"participant": ["P1", "P2", "P1", "P2", "P3"],
                      "sample": ["a", "a", "b", "b", "a"],
                      "rating": [np.nan, 5.0, 3.0, 4.0, 6.0]})
    m, subjects, levels = wide_means(d, "rating", "sample", "participant")
    got = {s: dict(zip(levels, row, strict=True)) for s, row in zip(subjects, m, strict=True)}
    assert got["P1"]["b"] == 3.0 and np.isnan(got["P1"]["a"])
    assert got["P2"] == {"a": 5.0, "b": 4.0} and got["P3"]["a"] == 6.0
    pw = A.pairwise_ttests(pd.concat([d, d.assign(participant=d["participant"] + "x")]),
                           "rating", "sample", "participant")
    assert sorted(pw.attrs["excluded_subjects"]) == ["P1", "P1x", "P3", "P3x"]


def test_a_mixed_model_without_residual_variance_is_undefined_in_words():
    """Every participant gave each sample the same rating every time: no residual variance.
    It raised LinAlgError (or printed χ² = 1e30) and stopped the whole report."""
    rows = [(f"P{p}", s, float(k + (p % 3))) for p in range(6)
            for k, s in enumerate("abc") for _ in range(2)]
    d = pd.DataFrame(rows, columns=["participant", "sample", "rating"])
    with pytest.raises(A.StatsError, match="no residual variance"):
        mixed_oneway(d, "rating", "sample", "participant")


def test_the_wilcoxon_floor_allows_for_ties():
    """With ties the normal approximation goes below 2/2ⁿ: six equal positive differences
    give p = .0197 < 2/64, so the stated floor must be the smaller."""
    from analysis.stats import signed_rank_test
    from analysis.stats.nonparametric import _signrank_min_p

    r = signed_rank_test(np.full(6, 0.5))
    assert r["method"] == "normal" and r["p"] < 2 / 64
    assert _signrank_min_p(6) <= r["p"] + 1e-15


def test_a_most_significant_p_that_underflowed_is_a_bound():
    out = _p_bounds({"groups": {"wood": {"most_significant_p": 0.0, "F": 3.0}}})
    assert out["groups"]["wood"] == {"most_significant_p": "< 2.3e-308", "F": 3.0}


def test_the_ordinal_model_survives_a_participant_always_at_the_top():
    """A participant who always gave the top rating pushes their posterior mode far out;
    unclipped Newton steps once overshot to NaN and kept it for every later call."""
    from analysis.ordinal import ordinal_mixed

    rng = np.random.default_rng(3)
    rows = [(f"P{p}", s, 7 if p == 0 else int(np.clip(np.rint(4 + k + rng.normal()), 1, 7)))
            for p in range(8) for k, s in enumerate("abc") for _ in range(4)]
    d = pd.DataFrame(rows, columns=["participant", "sample", "rating"])
    r = ordinal_mixed(d, "rating", "sample", "participant").iloc[0]
    assert np.isfinite(r["lr"]) and r["lr"] > 0 and r["converged"]


def test_a_separated_ordinal_fit_says_its_estimates_diverged_instead_of_an_se_of_0():
    """Found on 4 simulated participants of the realism protocol: every rating of some
    samples lay above every rating of others, the cumulative-link model's estimates ran to
    −46 log-odds, and the report printed SE 0 and a CI of zero width (negative variances
    clipped to 0). An estimate that diverged has no SE or CI, and says so."""
    import pandas as pd

    from analysis.ordinal import DIVERGED_LOGITS, ordinal_mixed

    rows = [{"p": f"P{i}", "s": s, "r": r} for i in range(4)
            for s, rs in (("low", (1, 2, 1, 2)), ("high", (3, 3, 3, 3)), ("mid", (2, 1, 2, 3)))
            for r in rs]
    om = ordinal_mixed(pd.DataFrame(rows), "r", "s", "p")
    high = next(f for f in om.attrs["fixed"] if f["term"] == "s[high]")
    assert abs(high["estimate"]) > DIVERGED_LOGITS
    assert high["se"] is None and high["ci_low"] is None and high["ci_high"] is None
    assert high["note"].startswith("diverged")
    assert "diverged" in om["note"].iloc[0]
    mid = next(f for f in om.attrs["fixed"] if f["term"] == "s[mid]")  # overlaps 'low'
    assert mid.get("note") is None and 0 < mid["se"] < 10
