"""hapticlab's statistics against R, on studies built to be awkward (tests/r/studies.py).

The references in tests/r/references.csv were computed by tests/r/reference.R (the R call
is beside each value in the file) from the same rows; ``make test`` recomputes them when R
is installed and checks that the committed values still hold. Tolerances: 1e-9 relative
for closed forms (t, equivalence, Wilcoxon, Friedman, ANOVA and their p; a TOST t at the
margin itself, 0 here and 3e-16 in R, within 1e-9 of one standard error; p below 1e-300
compared on the log scale); 1e-6 for the CI of partial η², a root of the noncentral F found by two
root-finders (measured: 1.5e-8; R's side uses uniroot at 1e-12 on pf, because
effectsize::F_to_eta2 misses the root by up to 0.03 at F near 0); 1e-5 relative for
the REML fits: hapticlab's profiled search stops at 1e-12 in the variance ratio, lme4's
bobyqa at its default tolerance (the largest differences measured: χ² 4e-7, SDs 6e-8,
p 3e-6); for the ordinal mixed model, whose likelihood
is a quadrature (20 adaptive nodes on both sides) maximised by L-BFGS-B here and by
clmm's Newton there, 1e-4 × max(|value|, 1) (measured: log-likelihood and LR 4e-11
relative, coefficients and SEs 2.2e-5 logit units at most).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import analysis as A
from analysis.ordinal import ordinal_mixed
from analysis.stats import mixed_oneway
from analysis.study import rating_factorial

R_DIR = Path(__file__).resolve().parents[1] / "r"
sys.path.insert(0, str(R_DIR))
import studies  # noqa: E402

REF = pd.read_csv(R_DIR / "references.csv")
CLOSED = 1e-9
FITTED = 1e-5
ROOT = 1e-6
ORDINAL = 1e-4
TOST_BOUND = 0.5  # rating points, as tests/r/reference.R


def _ours_oneway(d: pd.DataFrame) -> dict[tuple[str, str, str], float]:
    """(analysis, term, stat) → value, as hapticlab computes them from ``d``."""
    out = {}
    args = (d, "rating", "sample", "participant")
    holm, fdr = A.pairwise_ttests(*args, "holm"), A.pairwise_ttests(*args, "fdr_bh")
    for r, pf in zip(holm.itertuples(), fdr["p_corr"], strict=True):
        key = f"{r.A}|{r.B}"
        out.update({("ttest", key, "t"): r.t, ("ttest", key, "df"): r.dof,
                    ("ttest", key, "p"): r.p_unc, ("ttest", key, "mean_diff"): r.mean_diff,
                    ("ttest", key, "ci_low"): r.ci_low, ("ttest", key, "ci_high"): r.ci_high,
                    ("ttest", key, "p_holm"): r.p_corr, ("ttest", key, "p_fdr"): pf})
    for r in A.equivalence_ttests(*args, bound=TOST_BOUND).itertuples():
        key = f"{r.A}|{r.B}"
        out.update({("tost", key, "p"): r.p, ("tost", key, "t_lower"): r.t_lower,
                    ("tost", key, "t_upper"): r.t_upper, ("tost", key, "ci_low"): r.ci_low,
                    ("tost", key, "ci_high"): r.ci_high})
    for r in A.pairwise_wilcoxon(*args, "holm").itertuples():
        key = f"{r.A}|{r.B}"
        out.update({("wilcoxon", key, "V"): r.V, ("wilcoxon", key, "p"): r.p_unc,
                    ("wilcoxon", key, "p_holm"): r.p_corr})
    fr = A.friedman(*args).iloc[0]
    out.update({("friedman", "sample", "Q"): fr.Q, ("friedman", "sample", "p"): fr.p_unc})
    aov = A.rm_anova(*args).iloc[0]
    for stat in ("F", "DF_err", "p_unc", "np2", "np2_ci_low", "np2_ci_high", "eps_gg", "p_gg",
                 "eps_hf", "W_mauchly", "p_spher"):
        out[("anova", "sample", stat)] = aov[stat]
    mx = mixed_oneway(*args).iloc[0]
    out.update({("mixed", "sample", "chi2"): mx.chi2, ("mixed", "sample", "p"): mx.p_unc,
                ("mixed", "sample", "sd_subject"): mx.sd_subject,
                ("mixed", "sample", "sd_resid"): mx.sd_resid})
    om = ordinal_mixed(*args)
    out.update({("ordinal", "sample", k): float(om[k].iloc[0])
                for k in ("lr", "loglik", "sd_subject")})
    for t in om.attrs["thresholds"]:
        out[("ordinal_coef", t["between"], "estimate")] = t["estimate"]
        out[("ordinal_coef", t["between"], "se")] = t["se"]
    for f in om.attrs["fixed"]:
        key = f["term"].split("[", 1)[1].rstrip("]")
        out[("ordinal_coef", key, "estimate")] = f["estimate"]
        out[("ordinal_coef", key, "se")] = f["se"]
    if d["group"].fillna("").astype(str).str.len().gt(0).any():
        names = {"sample": "sample", "group": "group", "sample * group": "sample:group"}
        for r in mixed_oneway(*args, between="group").itertuples():
            out[("mixed_group", names[r.Source], "chi2")] = r.chi2
            out[("mixed_group", names[r.Source], "p")] = r.p_unc
    return out


def _ours_factorial(d: pd.DataFrame) -> dict[tuple[str, str, str], float]:
    out = {}
    res = rating_factorial(d, studies.FACTORS, by="block", normalize="zscore_block")
    for block, v in res.items():
        for r in v["anova"].itertuples():
            key = f"{block}|{r.Source}"
            out.update({("factorial", key, "F"): r.F, ("factorial", key, "p_unc"): r.p_unc,
                        ("factorial", key, "np2"): r.np2,
                        ("factorial", key, "np2_ci_low"): r.np2_ci_low,
                        ("factorial", key, "np2_ci_high"): r.np2_ci_high})
    return out


def _ours_crossed(d: pd.DataFrame) -> dict[tuple[str, str, str], float]:
    out = {}
    aov = A.rm_anova(d, "rating", ["hand", "texture"], "participant")
    for r in aov.to_dict(orient="records"):
        for stat in ("F", "p_unc", "np2", "eps_gg", "p_gg", "eps_hf", "W_mauchly", "p_spher"):
            if stat in r and not pd.isna(r[stat]):
                out[("crossed", r["Source"], stat)] = r[stat]
    return out


OURS = {"factorial": _ours_factorial, "crossed_2x3": _ours_crossed}


def _close(ours: float, ref: float, rel: float) -> bool:
    if ref != 0 and abs(ref) < 1e-300:  # p at the edge of doubles: compare log p
        return abs(np.log(ours) - np.log(ref)) <= rel * abs(np.log(ref))
    return abs(ours - ref) <= rel * abs(ref) + 1e-300


@pytest.mark.parametrize("study", list(studies.STUDIES))
def test_every_statistic_matches_r(study):
    d = studies.STUDIES[study]()
    ours = OURS.get(study, _ours_oneway)(d)
    ref = REF[REF["study"] == study]
    assert len(ref) >= 19
    wrong = []
    for r in ref.itertuples():
        key = (r.analysis, r.term, r.stat)
        assert key in ours, f"{study}: hapticlab has no {key} (R: {r.call})"
        if r.analysis.startswith("ordinal"):  # logit units: relative, floor of 1
            ok = abs(float(ours[key]) - float(r.value)) <= ORDINAL * max(abs(r.value), 1.0)
        elif r.analysis == "tost" and r.stat.startswith("t_"):
            # a t at the margin itself is 0 here and 3e-16 in R (mean − bound rounded):
            # t is in standard errors, so 1e-9 of one is the floor
            ok = abs(float(ours[key]) - float(r.value)) <= CLOSED * max(abs(r.value), 1.0)
        else:
            ok = _close(float(ours[key]), float(r.value),
                        FITTED if r.analysis.startswith("mixed") else
                        ROOT if r.stat.startswith("np2_ci") else CLOSED)
        if not ok:
            wrong.append(f"{key}: ours {ours[key]!r}, R {r.value!r} ({r.call})")
    n_ours = sum(1 for k in ours if k[0] in set(ref["analysis"]))
    assert not wrong, f"{len(wrong)} of {len(ref)} differ:\n" + "\n".join(wrong[:20])
    assert n_ours == len(ref), "hapticlab computes values R has no reference for"


def test_the_studies_reach_the_cases_they_were_built_for():
    """Ties in the Wilcoxon tests, exact p where there are none, and listwise exclusion:
    without them the comparison above would prove less than it says."""
    wx = A.pairwise_wilcoxon(studies.oneway_clean(), "rating", "sample", "participant")
    assert (wx["method"] == "normal").sum() > 40  # tied or zero differences
    small = A.pairwise_wilcoxon(studies.oneway_small(), "rating", "sample", "participant")
    assert (small["method"] == "exact").any()
    pw = A.pairwise_ttests(studies.oneway_messy(), "rating", "sample", "participant")
    assert pw.attrs["excluded_subjects"] == ["P03"]


@pytest.mark.r
@pytest.mark.slow
@pytest.mark.skipif(shutil.which("Rscript") is None,
                    reason="R missing: `make test` installs r-base-core and r-cran-*")
def test_r_still_computes_the_committed_references(tmp_path):
    sys.path.insert(0, str(R_DIR))
    from make_references import compute

    fresh = compute(tmp_path / "references.csv")
    key = ["study", "analysis", "term", "stat"]
    both = REF.merge(fresh, on=key, suffixes=("", "_now"), how="outer", indicator=True)
    assert (both["_merge"] == "both").all(), both[both["_merge"] != "both"][key]
    for r in both.itertuples():
        assert _close(float(r.value_now), float(r.value), CLOSED), (r.study, r.term, r.stat)
