"""Paired comparisons: a phase design ``dv = "choice"`` (a ``comparison`` phase, two samples
felt one after the other and the one that felt more like real contact chosen). Per pair,
the share choosing each (exact binomial against 1/2, Holm over the pairs); per sample, the
share of its comparisons won; the bias towards the sample felt first
(:func:`analysis.study.choice_scores`)."""

from __future__ import annotations

import pandas as pd

from ..report_text import left_out_text, md_text, p_text, people
from ..report_text import table as _table
from ..study import choice_scores
from .base import AnalysisType

__all__ = ["COMPARISON"]


def _matches(phase: dict) -> bool:
    return phase.get("dv") == "choice"


def _analyse(rows: pd.DataFrame, phase: dict, alpha: float):
    return choice_scores(rows, list(phase.get("samples") or []) or None)


def _entry(r) -> dict:
    return {"pairs": r["pairs"], "samples": r["samples"], "order": r["order"],
            "n_subjects": r["n_subjects"], "n_choices": r["n_choices"],
            "exclusions": r["exclusions"], "n_selected": r["n_selected"]}


def _methods(res, phase: dict, design: dict) -> str:
    k = len(res["samples"])
    pairs = len(res["pairs"])
    return (f"{people(res['n_subjects'])} felt {pairs} pairs of {k} samples, each pair in "
            f"both orders, and chose the one that felt more like real contact "
            f"({res['n_choices']} choices). For each pair, the share choosing each sample "
            "(both orders pooled) is tested against 1/2 with a two-sided exact binomial "
            "test (as R's binom.test), p adjusted over the pairs by Holm–Bonferroni; each "
            "choice counts as independent, so a person's repeated choices of a pair are not "
            "told apart. Each sample's share of the comparisons it won orders the samples. "
            "The share of choices of the sample felt first is tested against 1/2 the same "
            "way: a bias of the procedure, which presenting both orders cancels in each "
            "pair's share." + left_out_text(res, "choice"))


def _summary(a: dict) -> str:
    head = f"**{md_text(a['id'])}** ({people(a['n_subjects'])}): "
    sig = [p for p in a["pairs"] if p["p_corr"] < 0.05]
    top, low = a["samples"][0], a["samples"][-1]
    o = a["order"][0]
    return (head + f"{len(sig)} of {len(a['pairs'])} pairs were chosen between unequally "
            f"(Holm, α = .05). Most often chosen: {top['sample']} "
            f"({100 * top['prop_won']:.0f} % of its {top['n']} comparisons); least: "
            f"{low['sample']} ({100 * low['prop_won']:.0f} %). The sample felt first was "
            f"chosen in {100 * o['prop_first']:.0f} % of {o['n']} choices ({p_text(o['p_unc'])}).")


def _markdown(a: dict) -> tuple[list[str], list[str]]:
    out = ["#### Samples (share of their comparisons won)\n", _table(a["samples"]),
           "\n#### Pairs (A chosen over B, both orders pooled; exact binomial against 1/2, "
           "Holm)\n", _table(a["pairs"])]
    # the smallest Holm-adjusted p any pair can reach: all its n choices one way
    floor = len(a["pairs"]) * min(2 * 0.5 ** r["n"] for r in a["pairs"])
    if floor >= 0.05:
        out.append(f"\nWith at most {max(r['n'] for r in a['pairs'])} choices a pair, the "
                   f"smallest Holm-adjusted p any pair can reach is {min(floor, 1.0):.2g} "
                   f"({len(a['pairs'])} pairs × 2 × 0.5^n, every choice one way): no pair "
                   "can reach .05 whatever the choices; more people, or repetitions, can.\n")
    out += ["\n#### Order of presentation (the sample felt first chosen)\n", _table(a["order"]),
            "\n#### Exclusions\n", _table(a["exclusions"]) if a["exclusions"] else
            "No participant of the selected sessions was left out.\n"]
    return out, []


def _figures(a: dict, data: pd.DataFrame, out) -> list[str]:
    return []  # the tables say it all; a preference-matrix figure is not drawn yet


COMPARISON = AnalysisType(
    name="comparison", matches=_matches, analyse=_analyse, entry=_entry, methods=_methods,
    summary=_summary, markdown=_markdown, figures=_figures, captions={})
