"""Thresholds of adaptive phases: a phase design ``dv = "forced_choice"`` (a ``staircase``
or ``questplus`` phase). Per participant and track, a psychometric function fitted by
maximum likelihood, its threshold at the phase's criterion from the posterior (median and
credible interval), beside the procedure's own estimate; per track, the group's Weber fractions
(:func:`analysis.thresholds.threshold_scores`)."""

from __future__ import annotations

import pandas as pd

from ..report_text import md_text, people
from ..report_text import table as _table
from ..thresholds import threshold_scores
from .base import AnalysisType

__all__ = ["THRESHOLD"]

_FUNCTION = {"weibull": "Weibull", "normal": "cumulative normal", "logistic": "logistic"}
_UNITS = {"log": "log10 of the comparison/standard ratio", "dB": "dB (20·log10 of the ratio)",
          "linear": "the parameter's own unit"}


def _matches(phase: dict) -> bool:
    return phase.get("dv") == "forced_choice"


def _analyse(rows: pd.DataFrame, phase: dict, alpha: float):
    return threshold_scores(rows, phase, alpha)


def _entry(r) -> dict:
    return {"fits": r["fits"], "group": r["group"], "parameter": r["parameter"],
            "units": r["units"], "procedure": r["procedure"], "criterion": r["criterion"],
            "function": r["function"], "lapse_max": r["lapse_max"],
            "gof_samples": r["gof_samples"], "n_subjects": r["n_subjects"],
            "unfit": r["unfit"], "design": r["design"]}


def _procedure_text(design: dict) -> str:
    if design.get("procedure") == "staircase":
        steps = ", ".join(f"{s:g}" for s in design["steps"])
        change = ", ".join(str(c) for c in design.get("change_after", []))
        return (f"a {design['down']}-down/1-up staircase (Levitt 1971; it converges on "
                f"{100 * design['converges_on']:.1f} % correct) from {design['start']:g}, in "
                f"steps of {steps}" + (f" changing after reversal {change}" if change else "")
                + f", bounded to {design['minimum']:g}–{design['maximum']:g}, stopping after "
                f"{design['stop_reversals']} reversals; its estimate is the mean intensity at "
                f"the reversals after the first {design['discard']}")
    return (f"QUEST+ (Watson 2017; the questplus package) over a Weibull's threshold, slope "
            f"({', '.join(f'{s:g}' for s in design['slopes'])}) and lapse "
            f"({', '.join(f'{s:g}' for s in design['lapses'])}) on "
            f"{len(design['intensities'])} intensities from {design['intensities'][0]:g} to "
            f"{design['intensities'][-1]:g}, for {design['trials']} answers a track; its "
            f"estimate is the posterior mean of the threshold at {design['criterion']:g} with "
            "the 95 % credible interval")


def _methods(res, phase: dict, design: dict) -> str:
    d = res["design"]
    catch = (f"; {100 * d['catch']:.0f} % of trials were catch trials at "
             f"{d['catch_intensity']:g}, answered but not given to the procedure"
             if d.get("catch") else "")
    level = round(100 * (1 - res["alpha"]))
    return (f"{people(res['n_subjects'])} chose which of two renderings, the standard and a "
            f"comparison with a larger {res['parameter']} felt one after the other in a drawn "
            f"order, had more of it (two-interval forced choice). Each track ran "
            f"{_procedure_text(d)}, at most {d['max_trials']} trials, its tracks interleaved"
            f"{catch}. The intensity is in {_UNITS[res['units']]}. For each participant and "
            f"track a {_FUNCTION[res['function']]} psychometric function of every valid "
            f"trial, the guess rate fixed at 1/2 and the lapse rate in "
            f"[0, {res['lapse_max']:g}], was fitted by maximum likelihood (the figures' "
            f"curves, the width and lapse in the appendix). The threshold is the intensity "
            f"at {100 * res['criterion']:g} % correct (lapses included): its posterior median "
            f"with the central {level} % credible interval, from the posterior over the "
            f"function's threshold, width and lapse on a grid, with psignifit 4's priors "
            f"(Schütt et al. 2016) but the width's flat in its logarithm; and its Weber "
            f"fraction (|comparison − standard| / standard). Goodness of fit is the deviance, "
            f"its p "
            f"from {res['gof_samples']} data sets drawn from the fitted function and refitted "
            f"(Wichmann & Hill 2001). Across participants, the Weber fractions of a track are "
            f"summarised by their geometric mean with a t-interval on their logarithms.")


def _summary(a: dict) -> str:
    head = f"**{md_text(a['id'])}** ({people(a['n_subjects'])}): "
    parts = [f"{g['track']} {100 * g['weber_geomean']:.0f} %" for g in a["group"]
             if g["weber_geomean"] is not None]
    return (head + f"Weber fractions of {a['parameter']} at {100 * a['criterion']:g} % correct "
            f"(geometric means): " + (", ".join(parts) or "none fitted") + ".")


def _markdown(a: dict) -> tuple[list[str], list[str]]:
    crit = f"{100 * a['criterion']:g} %"
    group = [{"track": g["track"], "n": g["n"], "criterion": crit,
              f"threshold ({a['units']})": g["threshold_mean"], "SD": g["threshold_sd"],
              "Weber (geo. mean)": g["weber_geomean"], "CI low": g["weber_ci_low"],
              "CI high": g["weber_ci_high"], "median": g["weber_median"]} for g in a["group"]]
    est = "reversal average" if a["procedure"] == "staircase" else "QUEST+ estimate"
    fits = [{"participant": f["participant"], "track": f["track"], "criterion": crit,
             "threshold": f["threshold"], "CI low": f["ci_low"], "CI high": f["ci_high"],
             "Weber": f["weber"], est: f["procedure_estimate"],
             "ML width": f["width"], "ML lapse": f["lapse"], "deviance": f["deviance"],
             "p_gof": f["gof_p"],
             "trials": f["n_trials"]} for f in a["fits"]]
    out = [f"Thresholds of {a['parameter']} at {crit} correct ({_FUNCTION[a['function']]} "
           f"fits, intensity in {_UNITS[a['units']]}).\n\n", _table(group)]
    notes = sorted({n for f in a["fits"] for n in f["ci_note"].split("; ") if n})
    if notes:
        out.append("\nOf the intervals of each participant's fits (appendix): "
                   + "; ".join(notes) + " (for some).\n")
    if a["procedure"] == "questplus":
        out.append("\nQUEST+ chose these intensities for its own model: its own posterior "
                   "estimate and credible interval are in the appendix beside the fit's "
                   "(`hapticlab bench thresholds` measures both against simulated "
                   "observers).\n")
    if a["unfit"]:
        out.append("\nNot fitted: " + "; ".join(f"{u['participant']} {u['track']} ({u['why']})"
                                             for u in a["unfit"]) + ".\n")
    return out, [f"#### {md_text(a['id'])}: each participant's fits\n", _table(fits)]


def _figures(a: dict, data: pd.DataFrame, out) -> list[str]:
    from .. import plots

    return plots.staircases(a, data, out) + plots.psychometric(a, data, out)


THRESHOLD = AnalysisType(
    name="threshold", matches=_matches, analyse=_analyse, entry=_entry, methods=_methods,
    summary=_summary, markdown=_markdown, figures=_figures,
    captions={"tracks": "Each track's intensity trial by trial, catch trials left out (one "
                        "line per participant; filled: right, open: wrong, ringed: a "
                        "reversal).",
              "psychometric": "Proportion correct at each intensity (area: trials there, "
                              "all participants); each participant's maximum-likelihood "
                              "function, which meets the criterion at its maximum-likelihood "
                              "threshold; each participant's stated threshold, the "
                              "posterior median (tick on the criterion, its credible "
                              "interval shaded); and the group's mean of the stated "
                              "thresholds (dashed), as in the table."},
    internal=("alpha",))
