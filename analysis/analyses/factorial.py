"""Factorial analysis of ratings: a phase design with factors ``within`` (two or three),
per block when ``by = "block"``: the repeated-measures ANOVA of the crossed design, simple
effects of significant interactions, each factor's preferred level, the most significant
factor and the best set (:func:`analysis.study.rating_factorial`)."""

from __future__ import annotations

import pandas as pd

from ..report_text import anova_rows, md_text, p_text, people, scale_text
from ..report_text import table as _table
from ..study import rating_factorial
from .base import AnalysisType

__all__ = ["FACTORIAL"]


def _matches(phase: dict) -> bool:
    within = list(phase.get("within") or [])
    return phase.get("dv") == "rating" and bool(within) and within != ["sample"]


def _analyse(rows: pd.DataFrame, phase: dict, alpha: float):
    return rating_factorial(rows, list(phase["within"]), phase.get("by"),
                            phase.get("normalize") or "none")


def _most(v: dict, alpha: float = 0.05) -> str:
    """The most significant factor, or a sentence saying none reached ``alpha``."""
    p = v["most_significant_p"]
    if p < alpha:
        return f"{v['most_significant']} ({p_text(p)})"
    return f"none significant (smallest {p_text(p)}, {v['most_significant']})"


def _entry(r) -> dict:
    return {"groups": {g: {"anova": anova_rows(v["anova"]),
                           "most_significant": v["most_significant"],
                           "most_significant_p": v["most_significant_p"],
                           "most_significant_text": _most(v),
                           "best_set": v["best_set"], "main_effects": v["main_effects"],
                           "sets": v["sets"], "exclusions": v["preflight"],
                           "simple_effects": v["simple_effects"],
                           "n_subjects": v["n_subjects"], "n_selected": v["n_selected"]}
                       for g, v in r.items()}}


#: the exclusions that leave a participant out of a group's ANOVA, in words for the methods
_WHY = {"never_reached": "never reached the block", "no_valid_rating": "no valid rating",
        "missing_cells": "a set missing", "constant_ratings": "every set rated the same"}


def _who(res: dict, by: bool) -> str:
    """Who was analysed: everyone, or how many of those selected entered each group's
    ANOVA and why the others did not (each is listed under the group's exclusions)."""
    n_sel = max(v["n_selected"] for v in res.values())
    counts = {g: v["n_subjects"] for g, v in res.items()}
    if all(c == n_sel for c in counts.values()):
        return f"{people(n_sel)} rated"
    why = [w for check, w in _WHY.items() if any(
        len(v["preflight"]) and (v["preflight"]["check"] == check).any() for v in res.values())]
    where = ", ".join(f"{c} in {g}" for g, c in counts.items()) if by else str(counts["all"])
    anova = "their block's ANOVA" if by else "the ANOVA"
    return (f"Of {people(n_sel)}, {where} entered {anova} (the others are listed under "
            f"exclusions with the reason: {', '.join(why)}); they rated")


def _methods(res, phase: dict, design: dict) -> str:
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
    return (f"{_who(res, bool(phase.get('by')))} {len(first['sets'])} sets per "
            f"{'block' if phase.get('by') else 'design'} ({shape} levels of "
            f"{', '.join(factors)}) on a {scale_text(design)} scale.{norm}{per} "
            f"{shape} repeated-measures ANOVA ({', '.join(factors)} within subjects; "
            "participants missing a cell left out, listwise; Greenhouse–Geisser and "
            "Huynh–Feldt corrections for effects with more than one degree of freedom); "
            "the most significant factor is the main effect with the smallest p when that "
            "p is below .05, otherwise none is named; the best set has the highest mean.")


def _summary(a: dict) -> str:
    n = max((v["n_subjects"] for v in a["groups"].values()), default=0)
    parts = []
    for g, v in a["groups"].items():
        best = v["best_set"]
        inter = [f"{r['Source'].replace(' * ', ' × ')} ({p_text(r.get('p_gg', r['p_unc']))})"
                 for r in v["anova"] if " * " in r["Source"]
                 and r.get("p_gg", r["p_unc"]) < 0.05]
        parts.append((f"{g}: most significant factor {_most(v)}"
                      if v["most_significant_p"] < 0.05 else
                      f"{g}: no main effect significant (smallest "
                      f"{p_text(v['most_significant_p'])}, {v['most_significant']})")
                     + (f"; interaction {', '.join(inter)} (simple effects below)"
                        if inter else "")
                     + f"; best set {best['sample']}")
    return f"**{md_text(a['id'])}** ({people(n)}): " + "; ".join(parts) + "."


def _markdown(a: dict) -> tuple[list[str], list[str]]:
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


def _figures(a: dict, data: pd.DataFrame, out) -> list[str]:
    from .. import plots

    return plots.factorial_interactions(a, out)


FACTORIAL = AnalysisType(
    name="factorial", matches=_matches, analyse=_analyse, entry=_entry, methods=_methods,
    summary=_summary, markdown=_markdown, figures=_figures,
    # a figure per group, named by it: its caption names the factors' interaction plots
    captions={"*": "Interaction plots of {group}: mean z-score per level of each pair of "
                   "factors."},
    # each participant's mean per cell: the interaction plots' 95 % CIs (report.json has
    # the sets' means; the ratings behind both are the trial files')
    internal=("*.cell_means",))
