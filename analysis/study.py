"""The analyses of the three studies, from the long table of :func:`analysis.load_sessions`."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import special, stats

from .load import tap_velocities
from .power import power_table, variance_components
from .stats import (
    StatsError,
    identification_scores,
    pairwise_ttests,
    preflight,
    rm_anova,
    zscore_by_subject,
)

__all__ = ["realism", "factorial", "identification", "device_summary", "mean_ci", "mean_cis"]

SUBJECT = "participant"


def mean_ci(values: np.ndarray, alpha: float = 0.05) -> tuple[float, float, float]:
    """Mean and its t-based 1 − alpha interval (the mean itself when n < 2)."""
    v = np.asarray(values, float)
    m = float(v.mean())
    if v.size < 2:
        return m, m, m
    h = stats.t.ppf(1 - alpha / 2, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size)
    return m, m - h, m + h


def mean_cis(m: np.ndarray, alpha: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Column means of a subject × level matrix and their t-based intervals, vectorised
    (NaN cells left out per column)."""
    n = (~np.isnan(m)).sum(axis=0)
    mean = np.nanmean(m, axis=0)
    sd = np.nanstd(m, axis=0, ddof=1)
    h = special.stdtrit(np.maximum(n - 1, 1), 1 - alpha / 2) * sd / np.sqrt(np.maximum(n, 1))
    h = np.where(n >= 2, h, 0.0)
    return mean, mean - h, mean + h


def _rated(data: pd.DataFrame, protocol: str, phase: str | None = None) -> pd.DataFrame:
    d = data[(data["protocol"] == protocol) & data["valid"] & data["rating"].notna()]
    if phase:
        d = d[d["phase"] == phase]
    if d.empty:
        raise StatsError(f"no valid rated trials of protocol {protocol!r}"
                         + (f" in phase {phase!r}" if phase else ""))
    return d.copy()


def _groups(levels: list[str], pw: pd.DataFrame, alpha: float) -> list[list[str]]:
    """Samples not distinguishable at alpha: connected components of 'not different' pairs."""
    parent = {s: s for s in levels}

    def find(s):
        while parent[s] != s:
            parent[s] = parent[parent[s]]
            s = parent[s]
        return s

    for r in pw.itertuples():
        if r.p_corr >= alpha:
            parent[find(r.A)] = find(r.B)
    comp: dict[str, list[str]] = {}
    for s in levels:
        comp.setdefault(find(s), []).append(s)
    return sorted(comp.values(), key=lambda g: -len(g))


def realism(data: pd.DataFrame, alpha: float = 0.05) -> dict:
    """Realism study: per-sample means with CIs (raw and z), per-subject averages, all
    pairwise paired t-tests (Holm and FDR), groups not distinguishable, one-way RM ANOVA."""
    d = _rated(data, "realism", "testing")
    d["rating_z"] = zscore_by_subject(d, "rating", SUBJECT)
    subj = d.groupby([SUBJECT, "sample"], observed=True)[["rating", "rating_z"]].mean()
    samples = []
    for s, g in subj.groupby(level="sample", observed=True):
        m, lo, hi = mean_ci(g["rating"].to_numpy())
        mz, loz, hiz = mean_ci(g["rating_z"].to_numpy())
        samples.append({"sample": s, "n": int(len(g)), "mean": m, "ci_low": lo, "ci_high": hi,
                        "mean_z": mz, "ci_low_z": loz, "ci_high_z": hiz})
    samples.sort(key=lambda r: -r["mean"])
    order = [r["sample"] for r in samples]
    d["sample"] = pd.Categorical(d["sample"], categories=order, ordered=True)
    d = d.sort_values("sample")
    pre = preflight(d, "rating", "sample", SUBJECT, scale="scale")
    holm = pairwise_ttests(d, "rating", "sample", SUBJECT, "holm", alpha)
    fdr = pairwise_ttests(d, "rating", "sample", SUBJECT, "fdr_bh", alpha)
    pw = holm.rename(columns={"p_corr": "p_holm"}).drop(columns="p_adjust")
    pw["p_fdr"] = fdr["p_corr"].to_numpy()
    pw["p_corr"] = pw["p_holm"]
    anova = rm_anova(d, "rating", "sample", SUBJECT)
    per_subject = (d.groupby([SUBJECT, "sample"], observed=True)["rating"].mean()
                   .unstack("sample").reset_index())
    # session length against precision and power, from this study's own variance
    vc = variance_components(d, "rating", "sample", SUBJECT)
    length = power_table(range(5, 31, 5), range(1, 6), effect=1.0, alpha=alpha,
                         comparisons=len(order) * (len(order) - 1) // 2, seed=0, **vc)
    return {"samples": samples, "pairwise": pw, "anova": anova,
            "session_length": {"variance_components": vc, "effect": 1.0, "table": length},
            "groups": _groups(order, holm, alpha), "per_subject": per_subject,
            "preflight": pre, "constant_pairs": holm.attrs.get("constant_pairs", []),
            "n_subjects": int(d[SUBJECT].nunique())}


FACTORS = ("frequency", "decay", "slope")


def factorial(data: pd.DataFrame) -> dict:
    """Factorial study: per material, a 2×2×2 within-subject ANOVA on ratings z-scored per
    subject, the most significant parameter, each parameter's preferred level (main
    effects), and the best set."""
    d = _rated(data, "factorial")
    d["rating_z"] = zscore_by_subject(d, "rating", SUBJECT)
    out = {}
    for material, g in d.groupby("block", observed=True):
        anova = rm_anova(g, "rating_z", list(FACTORS), SUBJECT)
        mains = anova[anova["Source"].isin(FACTORS)]
        most = mains.sort_values(["p_unc", "F"], ascending=[True, False]).iloc[0]
        means = (g.groupby(["sample", *FACTORS], observed=True)["rating_z"]
                 .agg(["mean", "count"]).reset_index().sort_values("mean", ascending=False))
        best = means.iloc[0]
        # each factor's levels: a participant's mean z over the four sets at that level,
        # averaged over participants (its 2-level F test is the paired t test of these)
        p_of = mains.set_index("Source")["p_unc"]
        effects = []
        for f in FACTORS:
            lv = g.groupby([SUBJECT, f], observed=True)["rating_z"].mean().unstack(f)
            lo, hi = float(lv["low"].mean()), float(lv["high"].mean())
            effects.append({"factor": f, "mean_z_low": lo, "mean_z_high": hi,
                            "difference": hi - lo, "p_unc": float(p_of[f]),
                            "preferred": "high" if hi > lo else "low"})
        out[str(material)] = {
            "anova": anova, "most_significant": str(most["Source"]),
            "main_effects": pd.DataFrame(effects),
            "most_significant_p": float(most["p_unc"]),
            "best_set": {"sample": str(best["sample"]), "mean_z": float(best["mean"]),
                         **{f: str(best[f]) for f in FACTORS}},
            "sets": means, "preflight": preflight(g, "rating_z", list(FACTORS), SUBJECT),
            "n_subjects": int(g[SUBJECT].nunique())}
    return out


def identification(data: pd.DataFrame) -> dict:
    """Identification test: the paper's Table 3 (all, last repetition, by group), chance level
    and a confusion matrix."""
    d = data[(data["protocol"] == "identification") & data["valid"]].copy()
    if d.empty:
        raise StatsError("no valid identification answers")
    d["truth"] = d["sample"].str.replace("+", ",", regex=False)
    res = identification_scores(d, SUBJECT, "correct", repetition="repetition", group="group",
                                answer="answer", truth="truth")
    return {"table": res["summary"], "confusion": res.get("confusion"), "chance": 1 / 6,
            "n_subjects": int(d[SUBJECT].nunique())}


def device_summary(data: pd.DataFrame) -> dict:
    """Incoming speeds over valid taps; saturations per participant and per sample."""
    valid = data[data["valid"]]
    v = tap_velocities(valid)
    sat = data[data["status"].isin(["saturated", "excluded_saturated"])]
    per_p = sat.groupby(SUBJECT).size().reindex(data[SUBJECT].unique(), fill_value=0)
    return {"velocity_mean": float(v.mean()) if v.size else 0.0,
            "velocity_sd": float(v.std(ddof=1)) if v.size > 1 else 0.0,
            "n_taps": int(v.size),
            "saturations_per_participant": {
                "mean": float(per_p.mean()) if len(per_p) else 0.0,
                "min": int(per_p.min()) if len(per_p) else 0,
                "max": int(per_p.max()) if len(per_p) else 0,
                "by_participant": {str(k): int(x) for k, x in per_p.items()}},
            "saturations_per_sample": {str(k): int(x) for k, x in
                                       sat.groupby("sample").size().items()}}
