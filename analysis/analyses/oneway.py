"""One-way repeated-measures analysis of ratings: a phase design ``within = ["sample"]``.

The ANOVA with its effect sizes, paired t-tests (Holm and Benjamini–Hochberg) with d_z,
compact letters, and the companions: Friedman and Wilcoxon tests, a linear mixed model and
a cumulative-link mixed model on trial-level ratings, and session length against power
(:func:`analysis.study.rating_oneway` computes them all).
"""

from __future__ import annotations

import pandas as pd

from ..report_text import anova_rows, md_text, nan_to_none, p_digits, p_text, people, scale_text
from ..report_text import table as _table
from ..study import rating_oneway
from .base import AnalysisType

__all__ = ["ONEWAY"]


def _matches(phase: dict) -> bool:
    return phase.get("dv") == "rating" and list(phase.get("within") or []) == ["sample"]


def _analyse(rows: pd.DataFrame, phase: dict, alpha: float):
    return rating_oneway(rows, alpha=alpha)


def _entry(r) -> dict:
    return {
        "samples": r["samples"], "anova": anova_rows(r["anova"]), "groups": r["groups"],
        "letters": r["letters"], "missing": r["missing"],
        "excluded_subjects": [str(x) for x in r["excluded_subjects"]],
        "pairwise": r["pairwise"][["A", "B", "mean_diff", "ci_low", "ci_high", "t", "dof",
                                   "p_unc", "p_holm", "p_fdr", "dz", "dz_ci_low",
                                   "dz_ci_high", "n"]],
        "ordinal": r["ordinal"] if isinstance(r["ordinal"], str) else {
            "friedman": r["ordinal"]["friedman"], "wilcoxon": r["ordinal"]["wilcoxon"],
            "agreement": _agreement(r["pairwise"], r["ordinal"]["wilcoxon"]),
            "wilcoxon_floor": r["ordinal"]["wilcoxon_floor"]},
        "models": r["models"], "model_estimates": r["model_estimates"],
        "omnibus": _omnibus(r),
        "anova_notes": r["anova"].attrs.get("notes", []),
        "session_length": r["session_length"], "n_subjects": r["n_subjects"],
        "exclusions": r["preflight"],
        "constant_pairs": [list(p) for p in r["constant_pairs"]],
        # a participant without a valid rating of a sample has no mean there: null
        "per_subject": nan_to_none(r["per_subject"].to_dict(orient="records"))}


def _omnibus(r: dict, alpha: float = 0.05) -> str:
    """One sentence: do the ANOVA and its companions agree that the samples differ?"""
    tests = [("the repeated-measures ANOVA", float(r["anova"]["p_gg"].iloc[0])
              if "p_gg" in r["anova"] else float(r["anova"]["p_unc"].iloc[0]))]
    if not isinstance(r["ordinal"], str):
        tests.append(("the Friedman test", float(r["ordinal"]["friedman"]["p_unc"].iloc[0])))
    for key, name in (("mixed", "the mixed model"), ("ordinal", "the ordinal model")):
        if not isinstance(r["models"][key], str):
            tests.append((name, float(r["models"][key]["p_unc"].iloc[0])))
    sig = [n for n, p in tests if p < alpha]
    a_txt = f"{alpha:g}".lstrip("0")  # APA: .05
    if len(sig) == len(tests):
        return f"All {len(tests)} omnibus tests find that the samples differ (p < {a_txt})."
    if not sig:
        return f"None of the {len(tests)} omnibus tests finds a difference (p ≥ {a_txt})."
    rest = [n for n, p in tests if p >= alpha]
    return (f"The omnibus tests disagree: {', '.join(sig)} "
            f"{'finds' if len(sig) == 1 else 'find'} a difference (p < {a_txt}); "
            f"{', '.join(rest)} {'does' if len(rest) == 1 else 'do'} not.")


def _agreement(pw: pd.DataFrame, wx: pd.DataFrame, alpha: float = 0.05) -> dict:
    """Where the paired t-tests and the Wilcoxon tests (both Holm) agree on significance."""
    t_sig = {(a, b) for a, b, p in zip(pw["A"], pw["B"], pw["p_holm"], strict=True) if p < alpha}
    w_sig = {(a, b) for a, b, p in zip(wx["A"], wx["B"], wx["p_corr"], strict=True) if p < alpha}
    pairs = set(zip(pw["A"], pw["B"], strict=True)) | set(zip(wx["A"], wx["B"], strict=True))
    only_t = sorted(f"{a}–{b}" for a, b in t_sig - w_sig)
    only_w = sorted(f"{a}–{b}" for a, b in w_sig - t_sig)
    return {"pairs": len(pairs), "significant_t": len(t_sig), "significant_wilcoxon": len(w_sig),
            "agree": len(pairs) - len(only_t) - len(only_w), "only_t": only_t,
            "only_wilcoxon": only_w}


def _methods(res, phase: dict, design: dict) -> str:
    k, n = res["n_levels"], res["n_subjects"]
    anova = res["anova"].iloc[0]
    n_anova = int(anova["DF_err"] / max(1, anova["DF"]) + 1)
    if "W_mauchly" in res["anova"].columns and not pd.isna(anova.get("W_mauchly")):
        sph = ("sphericity by Mauchly's test, with Greenhouse–Geisser and Huynh–Feldt "
               "corrections")
    elif k == 2:
        sph = "two levels, so sphericity holds by construction"
    else:
        sph = (f"Mauchly's test is undefined with {people(n_anova)} for {k} samples "
               "(singular covariance), so the Greenhouse–Geisser-corrected p is reported")
    pairs = k * (k - 1) // 2
    const = len(res["constant_pairs"])
    tested = f"all {pairs} pairs of samples" + (
        f" ({const} pair(s) whose difference is the same for every participant are "
        "listed, not tested)" if const else "")
    excl = res["preflight"]
    missing = excl[excl["check"] == "missing_cells"] if len(excl) else excl
    absent = excl[excl["check"].isin(["never_reached", "no_valid_rating"])] if len(excl) \
        else excl
    ex_txt = ""
    if len(absent):
        ex_txt = (f" {int(absent['n_excluded'].sum())} participant(s) of the selected "
                  "sessions left no valid rating in this phase (never reached it, or every "
                  "attempt excluded) and are listed under exclusions.")
    if len(missing):
        left = int(missing["n_excluded"].sum())
        ex_txt += (f" {left} participant(s) missing a sample were left out of the ANOVA "
                  + ("and of every t-test (listwise, as pingouin and JASP)."
                     if res.get("missing", "listwise") == "listwise" else
                     "(listwise) and of the t-tests of the pairs they miss (pairwise, "
                     "on request)."))
    return (f"{people(n)} rated {k} samples on a {scale_text(design)} scale, "
            f"{res['repetitions']} time(s) each (median); ratings were averaged per "
            f"participant and sample. One-way repeated-measures ANOVA on {n_anova} "
            f"participants with every sample (sample within subjects; {sph}); effect sizes "
            "partial η² (95 % CI by inverting the noncentral F, η² = λ / (λ + df_error), "
            "as R's effectsize) and generalized η² (Olejnik & Algina 2003). Paired two-sided "
            f"t-tests on {tested}, p adjusted by Holm–Bonferroni and, separately, by "
            "Benjamini–Hochberg; d_z = mean difference / SD of the differences; 95 % "
            "confidence intervals from the t distribution (for d_z: from the noncentral t). "
            "Ordinal companions: a Friedman test with Kendall's W and Wilcoxon signed-rank "
            "tests of every pair (Holm), on the same participants (p exact below 50 "
            "non-zero differences without ties, otherwise normal with tie and continuity "
            "corrections, as R's wilcox.test); on trial-level ratings, "
            "keeping participants with missing cells, a linear mixed model (random "
            "intercept per participant, REML; sum-to-zero contrasts, type-III Wald test "
            "of each term, as R's car::Anova(lmer(...), type = 3); with no "
            "random slope it tests samples against trial noise, more liberally than the "
            "ANOVA when participants disagree about samples) and a "
            "cumulative-link logit mixed model (random intercept per participant, "
            "maximum likelihood by 20-node adaptive Gauss–Hermite quadrature, "
            "likelihood-ratio test of sample; as R's ordinal::clmm with nAGQ = 20). "
            "Both models' estimates, variance components and thresholds are in the "
            "appendix. "
            "Values within 1e-9 of the ratings' spread count as equal, in differences, "
            "ties between ranks and zero variances (averaging in floating point makes "
            "7/3 − 2 and 2 − 5/3 different doubles). Letters "
            "(compact letter display, Piepho 2004): samples sharing a letter are not "
            f"significantly different (Holm p ≥ .05), pair by pair.{ex_txt}")


def _summary(a: dict) -> str:
    n = a["n_subjects"]
    n_tests = a["anova"][0]["n"]
    count = people(n) if n_tests == n else (  # every count printed is the n of its test
        f"{people(n)}, {n_tests} with every sample in the ANOVA and paired tests")
    aov = a["anova"][0]
    eps = aov.get("eps_gg")
    p = aov.get("p_gg", aov["p_unc"])
    dfs = (f"{aov['DF'] * eps:.2g}, {aov['DF_err'] * eps:.3g}" if eps is not None
           else f"{aov['DF']}, {aov['DF_err']}")
    top, low = a["samples"][0], a["samples"][-1]
    sig = sum(1 for r in a["pairwise"] if r["p_holm"] < 0.05)
    words = "differed" if p < 0.05 else "did not differ detectably"
    return (f"**{md_text(a['id'])}** ({count}): "
            f"ratings {words} among the {len(a['samples'])} samples, "
            f"F({dfs}) = {aov['F']:.3g}, {p_text(p)}"
            + (" (Greenhouse–Geisser)" if eps is not None else "")
            + f", ηp² = {aov['np2']:.2f}".replace("= 0.", "= .")
            + f". Highest: {top['sample']} (M = {top['mean']:.2f}, "
            f"95 % CI [{top['ci_low']:.2f}, {top['ci_high']:.2f}]); lowest: "
            f"{low['sample']} (M = {low['mean']:.2f}). {sig} of {len(a['pairwise'])} "
            "tested pairs differ (Holm). " + (a.get("omnibus") or ""))


def _markdown(a: dict) -> tuple[list[str], list[str]]:
    rows = [{"sample": r["sample"], "letters": r.get("letters", ""), "n": r["n"],
             "mean": r["mean"], "ci_low": r["ci_low"], "ci_high": r["ci_high"],
             "mean_z": r["mean_z"]} for r in a["samples"]]
    n_tests = a["anova"][0]["n"]
    left = a["n_subjects"] - n_tests
    out = [f"{people(a['n_subjects'])}"
           + (f"; {n_tests} rated every sample and are the n of the ANOVA, the t-tests and "
              f"the Wilcoxon tests ({left} left out listwise; the mixed models keep them)"
              if left else "") + ".\n\n#### Samples (mean rating, 95 % CI; letters: "
           "samples sharing a letter are not significantly different, Holm p ≥ .05 for every "
           "pair; z: per-participant z-scores)\n", _table(rows),
           "\n#### One-way repeated-measures ANOVA\n", _table(a["anova"])]
    out.extend(f"\n*{md_text(note)}.*\n" for note in a["anova_notes"])
    app = [f"\n### {md_text(a['id'])}: paired t-tests (d_z: Cohen's d for paired data, with "
           "its 95 % CI)\n", _table(a["pairwise"])]
    out.append("\n#### Companions: ordinal tests and trial-level models\n")
    o = a.get("ordinal")
    if isinstance(o, str) or o is None:
        out.append(f"Friedman and Wilcoxon: {o or 'not computed'}\n")
    else:
        g = o["agreement"]
        out.append(_table(o["friedman"]))
        out.append(f"\nOf {g['pairs']} pairs, {g['significant_t']} differ by the t-tests and "
                   f"{g['significant_wilcoxon']} by the Wilcoxon signed-rank tests (Holm, "
                   f"α = .05); the two agree on {g['agree']}"
                   + (f"; only by t: {', '.join(g['only_t'])}" if g["only_t"] else "")
                   + (f"; only by Wilcoxon: {', '.join(g['only_wilcoxon'])}"
                      if g["only_wilcoxon"] else "") + ".")
        floor = o.get("wilcoxon_floor", 0.0)
        if floor >= 0.05:
            out.append(f" With {people(a['anova'][0]['n'])} the smallest Holm-adjusted "
                       f"Wilcoxon p any pair can reach is {p_digits(min(floor, 1.0))} "
                       f"({g['pairs']} pairs × the smallest p of a signed-rank test with "
                       "that many differences, tied or not): no pair can reach .05 by Wilcoxon "
                       "whatever the data, so its count of 0 is not evidence against the "
                       "t-tests.")
        out.append("\n")
        app += [f"\n### {md_text(a['id'])}: Wilcoxon signed-rank tests (Holm; rbc: "
                "rank-biserial r)\n", _table(o["wilcoxon"])]
    for key, title in (("mixed", "Linear mixed model (random intercept per participant)"),
                       ("ordinal", "Cumulative-link mixed model (logit, random intercept "
                                   "per participant)"),
                       ("mixed_group", "Participant group as a between-subject factor "
                                       "(mixed model, sample × group)")):
        if key == "mixed_group" and key not in (a.get("models") or {}):
            continue
        m = (a.get("models") or {}).get(key)
        out.append(f"\n{title}: " + (f"{m}\n" if isinstance(m, str) or m is None else
                                      "\n\n" + _table(m)))
    names = {"mixed": "linear mixed model: fixed effects (sum-coded: each sample's mean "
                      "minus the mean of the sample means; rating points; 95 % Wald CI)",
             "ordinal": "cumulative-link mixed model: each sample against the first (log "
                        "odds of a higher rating; 95 % Wald CI) and the thresholds",
             "mixed_group": "linear mixed model with groups: fixed effects (sum-coded)"}
    for key, est in (a.get("model_estimates") or {}).items():
        app.append(f"\n### {md_text(a['id'])}: {names.get(key, key)}\n")
        app.append(_table(est.get("fixed") or []))
        if est.get("thresholds"):
            app.append("\n" + _table(est["thresholds"]))
    if a.get("omnibus"):
        out.append(f"\n{a['omnibus']}\n")
    out.append("\n#### Exclusions\n")
    out.append(_table(a["exclusions"]) if a["exclusions"] else
               "No participant or row was left out.\n")
    sl = a["session_length"]
    out.append("\n#### Session length against power and precision\n")
    if isinstance(sl, str):
        out.append(sl + "\n")
    else:
        vc = sl["variance_components"]
        out.append(f"Monte-Carlo, 10⁴ simulated studies per cell, with this study's SDs "
                   f"(trial {vc['sd_trial']:.2f}, participant×sample "
                   f"{vc['sd_interaction']:.2f}, participant {vc['sd_subject']:.2f}): power of "
                   f"a {sl['effect']:g}-point paired difference (Bonferroni over all pairs) and "
                   "the median 95 % CI half-width of a sample's mean (table in the "
                   "appendix).\n")
        app += [f"\n### {md_text(a['id'])}: session length against power\n",
                _table(sl["table"], ["subjects", "reps", "power", "ci_halfwidth"])]
    return out, app


def _figures(a: dict, data: pd.DataFrame, out) -> list[str]:
    from .. import plots

    files = plots.rating_means(a, out)
    if isinstance(a["result"]["session_length"], dict):
        files += plots.session_length(a, out)
    files += plots.rating_pmatrix(a, out)
    return files + plots.accel_traces(a, data, out)


ONEWAY = AnalysisType(
    name="oneway", matches=_matches, analyse=_analyse, entry=_entry, methods=_methods,
    summary=_summary, markdown=_markdown, figures=_figures,
    captions={"means": "Mean rating per sample with its 95 % CI.",
              "pvalues": "Holm-adjusted p of every pair of samples (the letters summarise "
                         "it).",
              "session_length": "Power and CI half-width against participants and "
                                "repetitions.",
              "accel_traces": "Contact acceleration of each sample: the recorded tap nearest "
                              "0.11 m/s incoming, scaled to that speed."})
