"""Thresholds of adaptive phases from their trials: a psychometric fit per participant and
track, the procedure's own estimate beside it, and a group summary with Weber fractions.

Reads what the session recorded: each valid trial's ``track``, ``intensity``, ``correct``
and ``state`` (the procedure after the answer, JSON), and the phase's recorded design
(``adaptive``: parameter, units, tracks and the procedure's settings; ``fit``: criterion,
function, lapse bound).
"""

from __future__ import annotations

import json
import math
import zlib

import numpy as np
import pandas as pd
from scipy import stats

from .psychometric import psychometric_fit
from .stats import StatsError

__all__ = ["threshold_scores", "weber", "states", "track_rows"]

SUBJECT = "participant"


def weber(x: float | None, units: str, value: float | None, direction: str = "up"
          ) -> float | None:
    """The Weber fraction |comparison − standard| / |standard| of intensity ``x`` in
    ``units`` (log10 ratio, dB or the parameter's own; ``value`` the standard's), None
    where ``x`` is. (The inverse of the procedure's own conversion,
    :func:`protocols.adaptive.value_at`, which the analysis does not import.)"""
    if x is None or not math.isfinite(x):
        return None
    if units == "linear":
        return abs(x / value) if value else None
    r = x if units == "log" else x / 20.0
    return 10.0 ** r - 1.0 if direction == "up" else 1.0 - 10.0 ** -r


def states(rows: pd.DataFrame) -> list[dict]:
    """Each row's recorded procedure state (``{}`` where none, or not JSON)."""
    out = []
    for text in rows["state"].fillna("").astype(str):
        try:
            v = json.loads(text) if text else {}
        except ValueError:
            v = {}
        out.append(v if isinstance(v, dict) else {})
    return out


def track_rows(rows: pd.DataFrame) -> pd.DataFrame:
    """The valid trials of an adaptive phase in order, with ``catch`` and ``reversal``
    from their states (an older session's rows without a track are left out)."""
    d = rows[rows["valid"] & rows["track"].fillna("").astype(str).ne("")].copy()
    d = d.sort_values([SUBJECT, "session", "trial_index"], kind="stable")
    st = states(d)
    d["catch"] = [bool(s.get("catch")) for s in st]
    d["reversal"] = [bool(s.get("reversal")) for s in st]
    d["_state"] = st
    d["intensity"] = pd.to_numeric(d["intensity"], errors="coerce")
    d["correct"] = pd.to_numeric(d["correct"], errors="coerce")
    return d


def _procedure_estimate(g: pd.DataFrame, design: dict) -> dict:
    """The staircase's reversal average (after the first ``discard``), or QUEST+'s last
    recorded estimate and credible interval."""
    g = g[~g["catch"]]
    if design.get("procedure") == "staircase":
        rev = g.loc[g["reversal"], "intensity"].to_numpy()[int(design.get("discard", 0)):]
        return {"procedure_estimate": float(np.mean(rev)) if len(rev) else None,
                "procedure_sd": float(np.std(rev, ddof=1)) if len(rev) > 1 else None,
                "reversals_used": int(len(rev))}
    last = g["_state"].iloc[-1] if len(g) else {}
    ci = last.get("ci") or [None, None]
    return {"procedure_estimate": last.get("estimate"), "procedure_ci_low": ci[0],
            "procedure_ci_high": ci[1]}


def threshold_scores(data: pd.DataFrame, phase: dict, alpha: float = 0.05,
                     gof_samples: int = 99, subject: str = SUBJECT) -> dict:
    """Thresholds of one adaptive phase.

    Parameters
    ----------
    data : DataFrame
        The phase's rows (:func:`analysis.load_sessions`).
    phase : dict
        Its recorded design (``adaptive``, ``fit``).
    alpha : float
        1 − the confidence level of each threshold's interval and of the group's.
    gof_samples : int
        Bootstrap samples of each fit's deviance (:func:`analysis.psychometric_fit`).

    Returns
    -------
    dict
        ``fits``: one row per participant and track — ``participant``, ``track``,
        ``standard``, ``direction``, ``criterion``, ``threshold`` [units] (the posterior
        median) with ``ci_low``, ``ci_high`` (its credible interval), ``ci_note``;
        ``threshold_ml`` (the maximum-likelihood function's, which the figures draw);
        ``weber`` (and its interval), ``width``, ``slope``,
        ``lapse``, ``deviance``, ``gof_p``, ``n_trials``, ``n_catch``, ``catch_correct``,
        ``procedure_estimate`` (the reversal average, or QUEST+'s) with its spread;
        ``group``: one row per track — ``n``, ``threshold_mean``, ``threshold_sd``,
        ``weber_geomean`` with ``weber_ci_low``/``weber_ci_high`` (t on log Weber fractions),
        ``weber_median``, ``criterion``; and ``parameter``, ``units``, ``procedure``,
        ``criterion``, ``function``, ``lapse_max``, ``gof_samples``, ``n_subjects``,
        ``unfit`` (participant and track whose data could not be fitted, and why).
    """
    design = phase.get("adaptive") or {}
    fit = phase.get("fit") or {}
    if not design:
        raise StatsError("the phase recorded no adaptive design (parameter, units, tracks)")
    crit, function = float(fit.get("criterion", 0.75)), fit.get("function", "weibull")
    lapse_max = float(fit.get("lapse_max", 0.06))
    units = design["units"]
    tracks = {t["name"]: t for t in design.get("tracks", [])}
    d = track_rows(data)
    if d.empty:
        raise StatsError("no valid trials of an adaptive track")
    fits, unfit = [], []
    for (pid, name), g in d.groupby([subject, "track"], sort=True):
        t = tracks.get(name, {})
        g = g.dropna(subset=["intensity", "correct"])
        if function == "weibull":
            g = g[g["intensity"] > 0]
        try:
            r = psychometric_fit(g["intensity"], g["correct"], function=function,
                                 criterion=crit, lapse_max=lapse_max, alpha=alpha,
                                 gof_samples=gof_samples,
                                 seed=zlib.crc32(f"{pid}/{name}".encode()))
        except ValueError as exc:
            unfit.append({"participant": str(pid), "track": name, "why": str(exc)})
            continue
        v, direction = t.get("value"), t.get("direction", "up")
        catch = g[g["catch"]]
        fits.append({
            "participant": str(pid), "track": name, "standard": t.get("standard"),
            "direction": direction, "criterion": crit, "threshold": r["threshold"],
            "ci_low": r["ci_low"], "ci_high": r["ci_high"], "ci_note": r["ci_note"],
            "threshold_ml": r["threshold_ml"],
            "weber": weber(r["threshold"], units, v, direction),
            "weber_ci_low": weber(r["ci_low"], units, v, direction),
            "weber_ci_high": weber(r["ci_high"], units, v, direction),
            "m": r["m"], "width": r["width"], "slope": r["slope"], "lapse": r["lapse"],
            "deviance": r["deviance"], "gof_p": r["gof_p"], "n_trials": r["n_trials"],
            "n_catch": int(len(catch)),
            "catch_correct": float(catch["correct"].mean()) if len(catch) else None,
            **_procedure_estimate(g, design)})
    if not fits:
        raise StatsError("no track could be fitted: " + "; ".join(
            f"{u['participant']} {u['track']}: {u['why']}" for u in unfit))
    return {"fits": fits, "group": _group(pd.DataFrame(fits), design, crit, alpha),
            "parameter": design["parameter"], "units": units,
            "procedure": design.get("procedure"), "criterion": crit, "function": function,
            "lapse_max": lapse_max, "gof_samples": gof_samples, "alpha": alpha,
            "n_subjects": int(d[subject].nunique()), "unfit": unfit,
            "design": {k: design[k] for k in design if k != "tracks"}}


def _group(fits: pd.DataFrame, design: dict, crit: float, alpha: float) -> list[dict]:
    out = []
    order = [t["name"] for t in design.get("tracks", [])]
    for name in sorted(set(fits["track"]), key=lambda n: (order.index(n)
                                                         if n in order else len(order), n)):
        g = fits[(fits["track"] == name) & fits["threshold"].notna()]
        w = g["weber"].dropna().to_numpy(dtype=float)
        w = w[w > 0]
        row = {"parameter": design["parameter"], "track": name,
               "standard": g["standard"].iloc[0] if len(g) else None, "criterion": crit,
               "n": int(len(g)),
               "threshold_mean": float(g["threshold"].mean()) if len(g) else None,
               "threshold_sd": float(g["threshold"].std(ddof=1)) if len(g) > 1 else None,
               "weber_geomean": float(np.exp(np.mean(np.log(w)))) if len(w) else None,
               "weber_ci_low": None, "weber_ci_high": None,
               "weber_median": float(np.median(w)) if len(w) else None}
        if len(w) > 1:
            lw = np.log(w)
            h = stats.t.ppf(1 - alpha / 2, len(w) - 1) * np.std(lw, ddof=1) / math.sqrt(len(w))
            row["weber_ci_low"] = float(np.exp(lw.mean() - h))
            row["weber_ci_high"] = float(np.exp(lw.mean() + h))
        out.append(row)
    return out
