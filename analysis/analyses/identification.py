"""Identification scores: a phase design ``dv = "answer"``. Percent correct against chance
(exact binomial over answers; with each participant as the unit, a sign test and a t-test
of their proportions), groups compared, and the confusion of surfaces presented and names
given (:func:`analysis.study.answer_scores`)."""

from __future__ import annotations

import pandas as pd

from ..report_text import left_out_text, md_text, p_text, people
from ..report_text import table as _table
from ..study import answer_scores
from .base import AnalysisType

__all__ = ["IDENTIFICATION"]


def _matches(phase: dict) -> bool:
    return phase.get("dv") == "answer"


def _analyse(rows: pd.DataFrame, phase: dict, alpha: float):
    return answer_scores(rows, phase.get("scoring") or "all_correct")


def _entry(r) -> dict:
    return {"table": r["table"], "chance": r["chance"], "scoring": r["scoring"],
            "n_subjects": r["n_subjects"], "per_participant": r["per_participant"],
            "groups_compared": r["groups_compared"], "exclusions": r["exclusions"],
            "n_selected": r["n_selected"],
            "confusion": None if r["confusion"] is None else
            {k: {kk: int(vv) for kk, vv in row.items()} for k, row in
             r["confusion"].to_dict(orient="index").items()}}


def _methods(res, phase: dict, design: dict) -> str:
    k = res["surfaces"]
    chance = 100 * res["chance"]
    rule = (f"a repetition counts as correct only when all {k} surfaces are named right "
            f"(chance 1/{k}! = {chance:.1f} %)" if res["scoring"] == "all_correct" else
            f"each surface counts on its own (chance 1/{k} = {chance:.1f} %)")
    return (f"{people(res['n_subjects'])} named {k} surfaces per repetition; "
            f"{rule}; percent correct is tested against chance with a one-sided exact "
            "binomial test over all answers, which treats a person's repeated answers as "
            "independent, and, with each participant as the unit, by a one-sided exact sign "
            "test of the participants above chance and a one-sample t-test of their "
            "proportions correct." + left_out_text(res, "answer"))


def _summary(a: dict) -> str:
    t = {r["scope"]: r for r in a["table"]}
    al = t.get("all")
    pp = a.get("per_participant")
    head = f"**{md_text(a['id'])}** ({people(a['n_subjects'])}): "
    txt = (head + f"{al['correct']} of {al['n']} repetitions ({al['percent']:.1f} %) named every "
           f"surface right (chance {100 * a['chance']:.1f} %; binomial over answers "
           f"{p_text(al['p_binom'])})") if al else head
    if isinstance(pp, list) and pp:
        r = pp[0]
        txt += (f"; with participants as the unit, {r['above']} of {r['n']} were above chance "
                f"(sign test {p_text(r['p_sign'])})")
    return txt + "."


def _markdown(a: dict) -> tuple[list[str], list[str]]:
    out = [f"Chance: {100 * a['chance']:.1f} % (scoring: {a['scoring']}).\n\n",
           _table(a["table"])]
    pp = a.get("per_participant")
    out.append("\n#### With each participant as the unit\n")
    out.append(f"{pp}\n" if isinstance(pp, str) or pp is None else _table(pp))
    gc = a.get("groups_compared")
    if gc:
        out.append(f"\n{gc['group_a']} ({people(gc['n_a'])}, {gc['mean_percent_a']:.1f} % "
                   f"correct) against {gc['group_b']} ({gc['n_b']}, {gc['mean_percent_b']:.1f} "
                   f"%): Mann–Whitney U = {gc['U']:g}, {p_text(gc['p_mwu'])} (two-sided, each "
                   "participant's proportion correct as one observation).\n")
    if a["confusion"]:
        out.append("\n#### Confusion (rows presented, columns answered)\n")
        out.append(_table([{"presented": k, **a["confusion"][k]} for k in a["confusion"]]))
    out.append("\n#### Exclusions\n")
    out.append(_table(a["exclusions"]) if a["exclusions"] else
               "No participant of the selected sessions was left out.\n")
    return out, []


def _figures(a: dict, data: pd.DataFrame, out) -> list[str]:
    from .. import plots

    return plots.confusion(a, out) if a["result"].get("confusion") is not None else []


IDENTIFICATION = AnalysisType(
    name="identification", matches=_matches, analyse=_analyse, entry=_entry,
    methods=_methods, summary=_summary, markdown=_markdown, figures=_figures,
    captions={"confusion": "Identification: surfaces presented (rows) against names given."})
