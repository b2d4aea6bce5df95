"""``hapticlab analyze``: the analyses the recorded designs call for → report.json / .md / .html.

Which sessions are pooled is chosen (:func:`analysis.load.select_sessions`) and shown: the
report opens with the table of sessions included and excluded, with the reason for each.
Sessions are grouped by the design they recorded; each analysed phase of each design gets
the analysis its design declares (:func:`analysis.study.analyse_phase`), and its methods
paragraph is written from the data: the scale, the counts, the pairs and the corrections
actually applied.

Re-running on the same files gives identical numbers (the analyses have no randomness,
and the JSON is written with sorted keys and rounded floats).
"""

from __future__ import annotations

import hashlib
import html
import json
import math
import platform
import re
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

from .load import DEVICE_COLUMNS, load_sessions, select_sessions
from .stats import StatsError
from .study import analyse_phase, analysed_phases, phase_rows

__all__ = ["analyze", "build_report", "methods_text"]

SIMULATED_NOTE = (
    "These data come from simulated participants, not people: the ratings and answers "
    "are those of a rehearsal model (app/participant_model.py) that judges features of the "
    "simulated device's signals. Each simulated person taps with their own speed, grasp "
    "and rhythm, compares four felt features (stop time, jolt, onset pitch, ring-down) "
    "with the reference it felt, and places that distance on the range of what it has "
    "felt so far; the parameters are listed in app/participant_model.py and the README. The "
    "report rehearses the study's analysis; its findings are not claims about human "
    "perception.")
DRY_RUN_NOTE = ("These data come from a dry run: a scripted responder answered at random to "
                "test the machinery. Nothing in this report is a finding.")


#: below this a p-value is not resolved by the distribution functions (the smallest
#: normal double); report.json gives the bound as text instead of a number
P_FLOOR = 2.3e-308



def _people(n) -> str:
    """'1 participant', '9 participants'."""
    return f"{n} participant{'' if n == 1 else 's'}"

def _clean(v, where: str = "report"):
    """JSON-safe, finite, rounded (12 significant digits) values; a non-finite number is an
    error naming where it is."""
    if isinstance(v, dict):
        return {str(k): _clean(x, f"{where}.{k}") for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x, f"{where}[{i}]") for i, x in enumerate(v)]
    if isinstance(v, pd.DataFrame):
        return _clean(v.to_dict(orient="records"), where)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f"a non-finite number reached the report at {where}: {f}")
        return float(f"{f:.12g}")
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def _p_bounds(v, key: str = ""):
    """``v`` with every p-value that underflowed (below :data:`P_FLOOR`, 0 included) given
    as the bound it is, in words: report.json never says p = 0."""
    if isinstance(v, dict):
        return {k: _p_bounds(x, k) for k, x in v.items()}
    if isinstance(v, list):
        return [_p_bounds(x, key) for x in v]
    is_p = key == "p" or key.startswith("p_") or key.endswith("_p")
    if isinstance(v, float) and is_p and 0 <= v < P_FLOOR:
        return f"< {P_FLOOR:g}"
    return v


def _nan_to_none(rows: list[dict]) -> list[dict]:
    return [{k: (None if isinstance(x, float) and math.isnan(x) else x) for k, x in r.items()}
            for r in rows]


def _scale_text(design: dict) -> str:
    s = design.get("scale")
    return f"{s['min']}–{s['max']}" if s else "—"


def methods_text(a: dict, design: dict) -> str:
    """The methods paragraph of one analysis, written from what was computed."""
    phase, res = a["phase_design"], a["result"]
    title = f"{design.get('title') or design['protocol']} ({design['protocol']}), phase " \
            f"'{a['phase']}'"
    if isinstance(res, str):
        return f"{title}: {res}."
    if a["type"] == "oneway":
        k, n = res["n_levels"], res["n_subjects"]
        anova = res["anova"].iloc[0]
        n_anova = int(anova["DF_err"] / max(1, anova["DF"]) + 1)
        if "W_mauchly" in res["anova"].columns and not pd.isna(anova.get("W_mauchly")):
            sph = ("sphericity by Mauchly's test, with Greenhouse–Geisser and Huynh–Feldt "
                   "corrections")
        elif k == 2:
            sph = "two levels, so sphericity holds by construction"
        else:
            sph = (f"Mauchly's test is undefined with {_people(n_anova)} for {k} samples "
                   "(singular covariance), so the Greenhouse–Geisser-corrected p is reported")
        pairs = k * (k - 1) // 2
        const = len(res["constant_pairs"])
        tested = f"all {pairs} pairs of samples" + (
            f" ({const} pair(s) whose difference is the same for every participant are "
            "listed, not tested)" if const else "")
        excl = res["preflight"]
        missing = excl[excl["check"] == "missing_cells"] if len(excl) else excl
        ex_txt = ""
        if len(missing):
            left = int(missing["n_excluded"].sum())
            ex_txt = (f" {left} participant(s) missing a sample were left out of the ANOVA "
                      + ("and of every t-test (listwise, as pingouin and JASP)."
                         if res.get("missing", "listwise") == "listwise" else
                         "(listwise) and of the t-tests of the pairs they miss (pairwise, "
                         "on request)."))
        return (f"{title}: {_people(n)} rated {k} samples on a {_scale_text(design)} scale, "
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
    if a["type"] == "factorial":
        factors = phase["within"]
        groups = list(res)
        first = res[groups[0]]
        shape = " × ".join(str(len(first["sets"][f].unique())) for f in factors)
        norm = {"zscore": " Ratings were z-scored within each participant over the phase "
                          "(mean 0, SD with divisor n 1; a participant who gave every set "
                          "the same rating has no z-scores and is left out, listed under "
                          "exclusions).",
                "zscore_block": " Ratings were z-scored within each participant and block "
                                "(each material's sets: mean 0, SD with divisor n 1, as the "
                                "reality-based models study; a participant who rated every "
                                "set of a block the same has no z-scores there and is left "
                                "out of that block's ANOVA, listed under exclusions)."}.get(
                                    phase.get("normalize") or "none", "")
        per = f" Per block ({', '.join(groups)}), a" if phase.get("by") else " A"
        n = max(v["n_subjects"] for v in res.values())
        return (f"{title}: {_people(n)} rated {len(first['sets'])} sets per "
                f"{'block' if phase.get('by') else 'design'} ({shape} levels of "
                f"{', '.join(factors)}) on a {_scale_text(design)} scale.{norm}{per} "
                f"{shape} repeated-measures ANOVA ({', '.join(factors)} within subjects; "
                "participants missing a cell left out, listwise; Greenhouse–Geisser and "
                "Huynh–Feldt corrections for effects with more than one degree of freedom); "
                "the most significant factor is the main effect with the smallest p when that "
                "p is below .05, otherwise none is named; the best set has the highest mean.")
    k = res["surfaces"]
    chance = 100 * res["chance"]
    rule = (f"a repetition counts as correct only when all {k} surfaces are named right "
            f"(chance 1/{k}! = {chance:.1f} %)" if res["scoring"] == "all_correct" else
            f"each surface counts on its own (chance 1/{k} = {chance:.1f} %)")
    return (f"{title}: {_people(res['n_subjects'])} named {k} surfaces per repetition; "
            f"{rule}; percent correct is tested against chance with a one-sided exact "
            "binomial test over all answers, which treats a person's repeated answers as "
            "independent, and, with each participant as the unit, by a one-sided exact sign "
            "test of the participants above chance and a one-sample t-test of their "
            "proportions correct.")


def _run(rows: pd.DataFrame, phase: dict):
    try:
        return analyse_phase(rows, phase)
    except StatsError as exc:
        return {"type": "not computed", "result": f"not computed: {exc}", "device": None}


def build_report(data: pd.DataFrame, selection: pd.DataFrame, filters: dict) -> tuple[dict, list]:
    """Every analysis the selected sessions' designs call for; returns the report content (not
    yet cleaned) and the analyses with their full results (for the figures)."""
    designs = data.attrs.get("designs", {})
    analyses = []
    for key in sorted(set(data["design_key"]) - {""},
                      key=lambda k: (designs[k]["protocol"], k)):
        design = designs[key]
        for phase in analysed_phases(design):
            rows = phase_rows(data, key, phase["name"])
            if rows.empty:
                continue
            a = _run(rows, phase)
            a.update({"id": f"{design['protocol']}/{phase['name']}", "protocol":
                      design["protocol"], "phase": phase["name"], "design_key": key,
                      "phase_design": phase, "scale": design.get("scale")})
            a["methods"] = methods_text(a, design)
            analyses.append(a)
    ids = [a["id"] for a in analyses]
    for a in analyses:  # the same protocol name under two designs: tell them apart
        if ids.count(a["id"]) > 1:
            a["id"] += f" (design {a['design_key'][:6]})"
    inc = selection[selection["included"]]
    kinds = sorted(set(inc["kind"]))
    intro = []
    if "simulated" in kinds:
        intro.append(SIMULATED_NOTE)
    if "dry-run" in kinds:
        intro.append(DRY_RUN_NOTE)
    shown = [f"{k}: {v}" for k, v in sorted(filters.items())
             if v and not (k == "ids" and v == "check")]  # the default check goes unsaid
    sel_text = (f"{len(inc)} of {len(selection)} sessions included ({', '.join(shown)}); "
                "every session found is listed below with the reason it is in or out.")
    methods = " ".join([*intro, sel_text, *(a["methods"] for a in analyses)])
    report = {
        "methods": methods, "kinds": kinds,
        "selection": {"filters": filters, "included": int(len(inc)),
                      "excluded": int(len(selection) - len(inc)),
                      "sessions": selection[["session_dir", "participant", "session",
                                             "protocol", "kind", "status", "rows", "included",
                                             "reason", *DEVICE_COLUMNS]].to_dict(
                                                 orient="records")},
        "analyses": [_report_entry(a) for a in analyses],
    }
    return report, analyses


#: ANOVA columns that exist only for effects with more than one degree of freedom
_SPHERICITY = ("eps_gg", "eps_hf", "p_gg", "p_hf", "W_mauchly", "p_spher")


def _anova_rows(aov: pd.DataFrame) -> list[dict]:
    """The ANOVA table as rows; a sphericity column is left out of a row where it does not
    apply (a one-df effect), instead of a NaN. Any other NaN still stops the report."""
    rows = []
    for r in aov.to_dict(orient="records"):
        rows.append({k: v for k, v in r.items()
                     if not (k in _SPHERICITY and isinstance(v, float) and math.isnan(v))})
    return rows


def _report_entry(a: dict) -> dict:
    r = a["result"]
    base = {"id": a["id"], "protocol": a["protocol"], "phase": a["phase"], "type": a["type"],
            "design": a["phase_design"], "scale": a["scale"], "methods": a["methods"],
            "device": a["device"]}
    if isinstance(r, str):
        return {**base, "result": r}
    if a["type"] == "oneway":
        base.update({
            "samples": r["samples"], "anova": _anova_rows(r["anova"]), "groups": r["groups"],
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
            "per_subject": _nan_to_none(r["per_subject"].to_dict(orient="records"))})
    elif a["type"] == "factorial":
        base["groups"] = {g: {"anova": _anova_rows(v["anova"]),
                              "most_significant": v["most_significant"],
                              "most_significant_p": v["most_significant_p"],
                              "most_significant_text": _most(v),
                              "best_set": v["best_set"], "main_effects": v["main_effects"],
                              "sets": v["sets"], "exclusions": v["preflight"],
                              "simple_effects": v["simple_effects"],
                              "n_subjects": v["n_subjects"]} for g, v in r.items()}
    else:
        base.update({"table": r["table"], "chance": r["chance"], "scoring": r["scoring"],
                     "n_subjects": r["n_subjects"], "per_participant": r["per_participant"],
                     "groups_compared": r["groups_compared"],
                     "confusion": None if r["confusion"] is None else
                     {k: {kk: int(vv) for kk, vv in row.items()} for k, row in
                      r["confusion"].to_dict(orient="index").items()}})
    return base


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


def analyze(data_dir: str | Path, out: str | Path, formats=("html", "md", "json"),
            protocol=None, kind=None, status: str = "complete", participants=None,
            since=None, until=None, drop_invalid: bool = False, ids: str = "check",
            sim_device: bool = False) -> dict:
    """Select sessions, run every analysis their designs call for, write the report.

    Parameters
    ----------
    data_dir : path
        Folder of session folders.
    out : path
        Where report.json / report.md / report.html and the figures go.
    formats : tuple of {'html', 'md', 'json'}
    protocol, kind, status, participants, since, until, ids, sim_device
        Filters, as :func:`analysis.load.select_sessions`.
    drop_invalid : bool
        Leave out (and list) recorded rows that cannot be analysed, instead of stopping
        with an error naming the first (:func:`analysis.load.load_sessions`).

    Returns
    -------
    dict
        The report's content (what report.json holds).
    """
    data = load_sessions(data_dir, drop_invalid=drop_invalid)
    filters = {"protocol": protocol, "kind": kind, "status": status,
               "participants": participants, "since": since, "until": until, "ids": ids,
               "sim_device": sim_device}
    selected, table = select_sessions(data, **filters)
    filters = {**filters, "kind": kind or _default_kind(table)}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    report, analyses = build_report(selected, table, filters)
    figures = []
    if analyses:
        from .plots import save_all

        figures = save_all(selected, analyses, out)
    inc = table[table["included"]]
    files = {k: v for k, v in data.attrs["files"].items()
             if any(str(Path(data_dir) / k).startswith(str(Path(d)) + "/")
                    for d in inc["session_dir"])}
    report["figures"] = figures
    keep = set(inc["session_dir"])
    report["selection"]["rows_left_out"] = [
        r for r in data.attrs.get("invalid_rows", [])
        if str(Path(r["file"]).parent) in keep]
    report["provenance"] = {
        "packages": {p: _ver(p) for p in ("numpy", "scipy", "pandas", "statsmodels", "patsy",
                                          "matplotlib", "markdown-it-py")},
        "python": platform.python_version(), "input_files": files,
        "seeds": sorted({int(s) for s in inc["seed"] if s is not None}),
        "sessions": int(len(inc)), "torn_lines_set_aside": data.attrs["torn"]}
    report = _clean(report)
    if "json" in formats:
        (out / "report.json").write_text(json.dumps(_p_bounds(report), indent=1,
                                                    sort_keys=True))
    md = _markdown(report)
    if "md" in formats:
        (out / "report.md").write_text(md)
    if "html" in formats:
        (out / "report.html").write_text(_html(md, report))
    return report


def _default_kind(table: pd.DataFrame) -> str:
    inc = table[table["included"]]
    return inc["kind"].iloc[0] if len(inc) else "human"


def _ver(p: str) -> str:
    try:
        return metadata.version(p)
    except metadata.PackageNotFoundError:
        return "not installed"


def _table(rows: list[dict], cols: list[str] | None = None) -> str:
    if not rows:
        return "*none*\n"
    cols = cols or list(dict.fromkeys(k for r in rows for k in r))  # every row's columns

    def fmt(v, col):
        if v is None:
            return "—"
        if isinstance(v, float):
            if col.startswith("p_") or col in ("p", "p_spher"):
                return _p_digits(v) if v >= 0.001 else "< .001"  # APA: no leading zero
            if v == 0:
                return "0"
            return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
        return str(v)

    def fmt_cell(v, col):  # escaped for Markdown: no cell can add columns or raw HTML
        return (html.escape(fmt(v, col), quote=False).replace("|", "\\|")
                .replace("\n", " ").replace("\r", " "))

    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(fmt_cell(r.get(c, ""), c) for c in cols) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _oneway_md(a: dict) -> tuple[list[str], list[str]]:
    """(the analysis' main text, its appendix tables)."""
    rows = [{"sample": r["sample"], "letters": r.get("letters", ""), "n": r["n"],
             "mean": r["mean"], "ci_low": r["ci_low"], "ci_high": r["ci_high"],
             "mean_z": r["mean_z"]} for r in a["samples"]]
    n_tests = a["anova"][0]["n"]
    left = a["n_subjects"] - n_tests
    out = [f"{_people(a['n_subjects'])}"
           + (f"; {n_tests} rated every sample and are the n of the ANOVA, the t-tests and "
              f"the Wilcoxon tests ({left} left out listwise; the mixed models keep them)"
              if left else "") + ".\n\n#### Samples (mean rating, 95 % CI; letters: "
           "samples sharing a letter are not significantly different, Holm p ≥ .05 for every "
           "pair; z: per-participant z-scores)\n", _table(rows),
           "\n#### One-way repeated-measures ANOVA\n", _table(a["anova"])]
    out.extend(f"\n*{_md_text(note)}.*\n" for note in a["anova_notes"])
    app = [f"\n### {_md_text(a['id'])}: paired t-tests (d_z: Cohen's d for paired data, with "
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
            out.append(f" With {_people(a['anova'][0]['n'])} the smallest Holm-adjusted "
                       f"Wilcoxon p any pair can reach is {_p_digits(min(floor, 1.0))} "
                       f"({g['pairs']} pairs × the smallest p of a signed-rank test with "
                       "that many differences, tied or not): no pair can reach .05 by Wilcoxon "
                       "whatever the data, so its count of 0 is not evidence against the "
                       "t-tests.")
        out.append("\n")
        app += [f"\n### {_md_text(a['id'])}: Wilcoxon signed-rank tests (Holm; rbc: "
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
        app.append(f"\n### {_md_text(a['id'])}: {names.get(key, key)}\n")
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
        app += [f"\n### {_md_text(a['id'])}: session length against power\n",
                _table(sl["table"], ["subjects", "reps", "power", "ci_halfwidth"])]
    return out, app


def _summary(a: dict) -> str:
    """One paragraph of findings in words, with APA-style numbers."""
    if "result" in a:
        return f"**{_md_text(a['id'])}**: {_md_text(a['result'])}"
    n = a.get("n_subjects") or max((v["n_subjects"] for v in a.get("groups", {}).values()
                                    if isinstance(v, dict)), default=0)
    head = f"**{_md_text(a['id'])}** ({_people(n)}): "
    if a["type"] == "oneway":
        n_tests = a["anova"][0]["n"]
        if n_tests != n:  # every count printed is the n of the test beside it
            head = (f"**{_md_text(a['id'])}** ({_people(n)}, {n_tests} with every sample "
                    "in the ANOVA and paired tests): ")
        aov = a["anova"][0]
        eps = aov.get("eps_gg")
        p = aov.get("p_gg", aov["p_unc"])
        dfs = (f"{aov['DF'] * eps:.2g}, {aov['DF_err'] * eps:.3g}" if eps is not None
               else f"{aov['DF']}, {aov['DF_err']}")
        top, low = a["samples"][0], a["samples"][-1]
        sig = sum(1 for r in a["pairwise"] if r["p_holm"] < 0.05)
        words = "differed" if p < 0.05 else "did not differ detectably"
        return (head + f"ratings {words} among the {len(a['samples'])} samples, "
                f"F({dfs}) = {aov['F']:.3g}, {_p(p)}"
                + (" (Greenhouse–Geisser)" if eps is not None else "")
                + f", ηp² = {aov['np2']:.2f}".replace("= 0.", "= .")
                + f". Highest: {top['sample']} (M = {top['mean']:.2f}, "
                f"95 % CI [{top['ci_low']:.2f}, {top['ci_high']:.2f}]); lowest: "
                f"{low['sample']} (M = {low['mean']:.2f}). {sig} of {len(a['pairwise'])} "
                "tested pairs differ (Holm). " + (a.get("omnibus") or ""))
    if a["type"] == "factorial":
        parts = []
        for g, v in a["groups"].items():
            best = v["best_set"]
            inter = [f"{r['Source'].replace(' * ', ' × ')} ({_p(r.get('p_gg', r['p_unc']))})"
                     for r in v["anova"] if " * " in r["Source"]
                     and r.get("p_gg", r["p_unc"]) < 0.05]
            parts.append((f"{g}: most significant factor {_most(v)}"
                          if v["most_significant_p"] < 0.05 else
                          f"{g}: no main effect significant (smallest "
                          f"{_p(v['most_significant_p'])}, {v['most_significant']})")
                         + (f"; interaction {', '.join(inter)} (simple effects below)"
                            if inter else "")
                         + f"; best set {best['sample']}")
        return head + "; ".join(parts) + "."
    t = {r["scope"]: r for r in a["table"]}
    al = t.get("all")
    pp = a.get("per_participant")
    txt = (head + f"{al['correct']} of {al['n']} repetitions ({al['percent']:.1f} %) named every "
           f"surface right (chance {100 * a['chance']:.1f} %; binomial over answers "
           f"{_p(al['p_binom'])})") if al else head
    if isinstance(pp, list) and pp:
        r = pp[0]
        txt += (f"; with participants as the unit, {r['above']} of {r['n']} were above chance "
                f"(sign test {_p(r['p_sign'])})")
    return txt + "."


def _most(v: dict, alpha: float = 0.05) -> str:
    """The most significant factor, or a sentence saying none reached ``alpha``."""
    p = v["most_significant_p"]
    if p < alpha:
        return f"{v['most_significant']} ({_p(p)})"
    return f"none significant (smallest {_p(p)}, {v['most_significant']})"


def _p_digits(p: float, alpha: float = 0.05) -> str:
    """p without ``p =`` and leading zero: 3 decimals below .1, else 2, and more when
    rounding would carry it across ``alpha`` (.0496 is ".0496", never ".050")."""
    digits = 3 if p < 0.1 else 2
    while digits < 15 and (p < alpha) != (round(p, digits) < alpha):
        digits += 1
    return f"{p:.{digits}f}".lstrip("0")


def _p(p: float) -> str:
    """APA style: ``p < .001``, else ``p = `` with 2–3 decimals and no leading zero, with as
    many more as it takes to show which side of .05 it lies."""
    if p < 0.001:
        return "p < .001"
    return "p = " + _p_digits(p)


def _factorial_md(a: dict) -> tuple[list[str], list[str]]:
    groups = a["groups"]
    factors = a["design"]["within"]
    rows = [{"group": g, **v["best_set"], "most significant": _most(v)}
            for g, v in groups.items()]
    out = ["#### Best set per group\n", _table(rows)]
    for g, v in groups.items():
        out.append(f"\n#### {g}: preferred level of each factor\n")
        effects = [{k: x for k, x in e.items() if not (k == "level_means" and "mean_z_low" in e)}
                   for e in v["main_effects"]]
        out.append(_table(effects))
        out.append(f"\n#### {g}: {' × '.join(factors)} ANOVA\n")
        out.append(_table(v["anova"]))
        if v.get("simple_effects"):
            out.append(f"\n#### {g}: simple effects of the significant interactions (Holm)\n")
            out.append(_table(v["simple_effects"]))
        out.append(f"\n#### {g}: exclusions\n")
        out.append(_table(v["exclusions"]) if v["exclusions"] else
                   "No participant or row was left out.\n")
    return out, []


def _identification_md(a: dict) -> tuple[list[str], list[str]]:
    out = [f"Chance: {100 * a['chance']:.1f} % (scoring: {a['scoring']}).\n\n",
           _table(a["table"])]
    pp = a.get("per_participant")
    out.append("\n#### With each participant as the unit\n")
    out.append(f"{pp}\n" if isinstance(pp, str) or pp is None else _table(pp))
    gc = a.get("groups_compared")
    if gc:
        out.append(f"\n{gc['group_a']} ({_people(gc['n_a'])}, {gc['mean_percent_a']:.1f} % "
                   f"correct) against {gc['group_b']} ({gc['n_b']}, {gc['mean_percent_b']:.1f} "
                   f"%): Mann–Whitney U = {gc['U']:g}, {_p(gc['p_mwu'])} (two-sided, each "
                   "participant's proportion correct as one observation).\n")
    if a["confusion"]:
        out.append("\n#### Confusion (rows presented, columns answered)\n")
        out.append(_table([{"presented": k, **a["confusion"][k]} for k in a["confusion"]]))
    return out, []


def _md_text(text: str) -> str:
    """User-given text (titles, names) in Markdown prose: no raw HTML gets through."""
    return html.escape(str(text), quote=False)


def _figures_of(a: dict, figures: list[str]) -> list[str]:
    """The PNG figures of analysis ``a``, named as :mod:`analysis.plots` names them."""
    from .plots import figure_prefix

    prefix = figure_prefix(a)
    return [f for f in figures if f.startswith(prefix) and f.endswith(".png")]


#: captions of the figures, by the end of their file name
CAPTIONS = {"means": "Mean rating per sample with its 95 % CI.",
            "pvalues": "Holm-adjusted p of every pair of samples (the letters summarise it).",
            "session_length": "Power and CI half-width against participants and repetitions.",
            "accel_traces": "Contact acceleration of each sample: the recorded tap nearest "
                            "0.11 m/s incoming, scaled to that speed.",
            "confusion": "Identification: surfaces presented (rows) against names given."}


def _caption(name: str, kind: str) -> str:
    """The caption of figure file ``name`` of an analysis of type ``kind``."""
    stem = name.rsplit(".", 1)[0]
    for key, text in CAPTIONS.items():
        if stem.endswith(key):
            return text
    if kind == "factorial":
        return (f"Interaction plots of {stem.rsplit('_', 1)[-1]}: mean z-score per level of "
                "each pair of factors.")
    return f"Figure {stem}."


def _markdown(rep: dict) -> str:
    """The report: a summary of findings, methods, one section per analysis (key tables and
    its figures with captions), then an appendix with the long tables and provenance."""
    general = rep["methods"]
    for a in rep["analyses"]:
        general = general.replace(" " + a["methods"], "").replace(a["methods"], "")
    out = ["# hapticlab report\n", "## Summary of findings\n"]
    out += [f"- {_summary(a)}" for a in rep["analyses"]] or [
        "No analysed phase has data in the selected sessions."]
    out += ["", "## Methods\n", _md_text(general) + "\n"]
    out.append("## Sessions included and excluded\n")
    out.append(_table(rep["selection"]["sessions"],
                      ["participant", "session", "protocol", "kind", "device_backend",
                       "device_id", "firmware", "status", "rows", "included", "reason",
                       "session_dir"]))
    appendix = []
    left_out = rep["selection"].get("rows_left_out") or []
    if left_out:
        out.append("\n### Recorded rows left out (--drop-invalid)\n")
        out.append(_table(left_out, ["participant", "phase", "sample", "reason", "file", "line"]))
    for a in rep["analyses"]:
        out.append(f"## {_md_text(a['id'])}\n")
        out.append(_md_text(a["methods"]) + "\n")
        if "result" in a:
            out.append(_md_text(a["result"]) + "\n")
            continue
        main, app = {"oneway": _oneway_md, "factorial": _factorial_md}.get(
            a["type"], _identification_md)(a)
        out.extend(main)
        appendix.extend(app)
        d = a["device"]
        if d and d["n_taps"]:
            sp = d["saturations_per_participant"]
            out.append("\n#### Device\n")
            out.append(f"Incoming speed over {d['n_taps']} valid taps: "
                       f"{d['velocity_mean']:.3f} ± {d['velocity_sd'] or 0:.3f} m/s (mean ± SD). "
                       f"Saturations per participant: mean {sp['mean']:.2f}, range "
                       f"{sp['min']}–{sp['max']}.\n\n")
            if d["saturations_per_sample"]:
                out.append(_table([{"sample": k, "saturations": v}
                                   for k, v in d["saturations_per_sample"].items()]))
        for f in _figures_of(a, rep["figures"]):
            cap = _md_text(_caption(f, a["type"]))
            out.append(f"\n![{cap}](<{f}>)\n")
            out.append(f"*Figure: {cap}*\n")
    out.append("\n## Appendix\n")
    out.extend(appendix)
    p = rep["provenance"]
    out.append("\n### Provenance\n")
    out.append(f"Python {p['python']}; " + ", ".join(f"{k} {v}" for k, v in
                                                     p["packages"].items()) + ".\n\n")
    out.append(f"Seeds: {p['seeds']}. Sessions: {p['sessions']}. Torn lines set aside: "
               f"{len(p['torn_lines_set_aside'])}.\n\n")
    out.append(_table([{"file": k, "sha256": v} for k, v in sorted(p["input_files"].items())]))
    return "\n".join(out)


#: tables longer than this are collapsed in the HTML (a click shows them)
COLLAPSE_ROWS = 12


def _collapse(match: re.Match) -> str:
    rows = match.group(0).count("<tr>") - 1  # the header row
    if rows > COLLAPSE_ROWS:
        return f"<details><summary>{rows} rows (show)</summary>{match.group(0)}</details>"
    return match.group(0)


def _html(md: str, rep: dict) -> str:
    """A self-contained page: the Markdown rendered by markdown-it-py (CommonMark with
    tables; raw HTML in the Markdown is shown as text, never interpreted), long tables
    collapsed."""
    from markdown_it import MarkdownIt

    body = MarkdownIt("commonmark", {"html": False}).enable("table").render(md)
    body = re.sub(r"<table>.*?</table>", _collapse, body, flags=re.S)
    body = re.sub(r"<h(\d)>(.*?)</h\1>", lambda m: '<h{0} id="{1}">{2}</h{0}>'.format(
        m.group(1), re.sub(r"[^0-9a-z]+", "-", html.unescape(m.group(2)).lower()).strip("-"),
        m.group(2)), body)  # anchors a reader can link to
    digest = hashlib.sha256(json.dumps(rep, sort_keys=True).encode()).hexdigest()[:16]
    style = ("body{font-family:sans-serif;max-width:1000px;margin:auto;line-height:1.4}"
             "table{border-collapse:collapse;font-size:12px;margin:6px 0}"
             "td,th{border:1px solid #ccc;padding:2px 6px}th{background:#f3f3f3}"
             "img{max-width:100%}"
             "h2{border-bottom:1px solid #ccc;margin-top:28px}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>hapticlab report</title>"
            f"<style>{style}</style></head><body>{body}<p><small>report digest "
            f"{digest}</small></p></body></html>")
