"""A study's analyses, chosen by the design each session recorded — never by a name.

Each analysed phase of a protocol declares its design (``protocols`` writes it into
session.json beside the protocol copy): the dependent variable, the within factors
(``sample`` for a one-way design over the phase's samples, or factor names the samples
carry), whether to analyse one block at a time, the normalisation, and how answers are
scored. :func:`analysis.analyses.analyse_phase` runs the matching analysis (each type
reported by its module in :mod:`analysis.analyses`):

* a one-way design over samples → :func:`rating_oneway`;
* a crossed design over factors (optionally per block) → :func:`rating_factorial`;
* answers → :func:`answer_scores`.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import special, stats

from ._kept import kept
from .load import tap_velocities
from .ordinal import ordinal_mixed
from .power import power_table, variance_components
from .stats import (
    StatsError,
    dz_ci,
    friedman,
    identification_scores,
    mixed_oneway,
    order_bias,
    p_adjust,
    pair_preferences,
    pairwise_ttests,
    pairwise_wilcoxon,
    participant_identification_test,
    preflight,
    rm_anova,
    zscore_by_subject,
)

__all__ = ["phase_rows", "rating_oneway", "rating_factorial", "answer_scores", "choice_scores",
           "device_summary", "mean_ci", "mean_cis", "analysed_phases"]

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


def analysed_phases(design: dict) -> list[dict]:
    """The phases of a recorded design that are analysed (role ``analysed``)."""
    return [p for p in design.get("phases", []) if p.get("role") == "analysed"]


def phase_rows(data: pd.DataFrame, design_key: str, phase: str) -> pd.DataFrame:
    """Rows of one phase of the sessions sharing a design; ``attrs["participants"]`` lists
    every participant of those sessions, whether or not they reached the phase (the
    analysis answers for each: :func:`participants_of`)."""
    mine = data["design_key"] == design_key
    rows = data[mine & (data["phase"] == phase)].copy()
    rows.attrs["participants"] = kept(sorted(map(str, data.loc[mine, SUBJECT].unique())))
    return rows


def participants_of(data: pd.DataFrame, subject: str = SUBJECT) -> list[str]:
    """The participants an analysis of ``data`` answers for: ``attrs["participants"]``
    when set (:func:`phase_rows`), else every participant with a row in ``data``."""
    names = data.attrs.get("participants")
    if names is None:
        names = data[subject].unique()
    return sorted(map(str, names))


def _exclusion(check: str, who, detail: str, policy: str) -> dict:
    who = sorted(map(str, who))
    return {"check": check, "detail": detail.format(n=len(who)), "policy": policy,
            "subjects_excluded": ",".join(who), "n_excluded": len(who)}


def not_analysed(everyone, reached, rated, where: str, what: str = "rating") -> list[dict]:
    """Exclusion rows (the preflight table's columns) for the participants of ``everyone``
    who have no valid ``what`` (``rating``, ``answer``, ``choice``) in ``where``: those
    with no row there at all (``never_reached``: their session stopped before it) and those
    whose rows there are none of them valid (``no_valid_<what>``: every attempt excluded,
    skipped or invalid)."""
    everyone, reached, rated = set(everyone), set(reached), set(rated)
    out = []
    never = everyone - reached
    if never:
        out.append(_exclusion("never_reached", never, "{n} participant(s) never reached "
                              f"{where} (their session stopped before it)",
                              "not in this analysis: nothing to analyse"))
    unrated = (everyone & reached) - rated
    if unrated:
        out.append(_exclusion(f"no_valid_{what}", unrated, f"{{n}} participant(s) reached "
                              f"{where} without a valid {what} in it (every attempt "
                              "excluded, skipped or invalid)",
                              "not in this analysis: nothing to analyse"))
    return out


def _rated(d: pd.DataFrame, dv: str) -> pd.DataFrame:
    d = d[d["valid"] & d[dv].notna()]
    if d.empty:
        raise StatsError(f"no valid trials with a {dv}")
    return d.copy()


def letter_groups(levels: list, pw: pd.DataFrame, alpha: float = 0.05,
                  p: str = "p_corr") -> list[list]:
    """The groups of a compact letter display, in letter order (see :func:`compact_letters`).

    Returns
    -------
    list of list
        One list of levels (in ``levels`` order) per letter; levels in one list are not
        significantly different, and every level is in at least one.
    """
    sig = [(r.A, r.B) for r in pw.itertuples() if getattr(r, p) < alpha]
    sig += [(a, b) for a, b, why in pw.attrs.get("constant_pairs", [])
            if not why.startswith("difference 0 ") and why != "fewer than 2 subjects"]
    groups = [set(levels)]
    for a, b in sig:  # insert, then absorb
        new = []
        for g in groups:
            if a in g and b in g:
                new += [g - {a}, g - {b}]
            else:
                new.append(g)
        groups = [g for g in new if g and not any(g < h for h in new)]
        groups = [g for i, g in enumerate(groups) if g not in groups[:i]]
    rank = {lv: i for i, lv in enumerate(levels)}
    groups.sort(key=lambda g: sorted(rank[x] for x in g))
    # sweep: a level leaves a letter when another letter still joins it to every level it
    # met there and it keeps a letter; a letter left empty goes
    for i, g in enumerate(groups):
        for x in sorted(g, key=rank.__getitem__):
            rest = [h for j, h in enumerate(groups) if j != i and x in h]
            if rest and all(any(y in h for h in rest) for y in g - {x}):
                g.discard(x)
    groups = [g for g in groups if g]
    groups.sort(key=lambda g: sorted(rank[x] for x in g))
    return [sorted(g, key=rank.__getitem__) for g in groups]


#: one character per letter, so that a level's letters read unambiguously: a–z, A–Z, α–ω
LETTERS = ("abcdefghijklmnopqrstuvwxyz" "ABCDEFGHIJKLMNOPQRSTUVWXYZ"
           "αβγδεζηθικλμνξοπρστυφχψω")


def compact_letters(levels: list, pw: pd.DataFrame, alpha: float = 0.05,
                    p: str = "p_corr") -> dict:
    """Compact letter display: levels sharing a letter are not significantly different.

    Piepho's (2004) insert-absorb-sweep: start with one group of all levels; for each
    significant pair, split every group holding both into one without each; drop groups
    contained in another; then take each level out of each letter that other letters make
    redundant. Two levels share a letter exactly when their pair is not significant
    (unlike chains of non-significant pairs, which are not transitive); a level may carry
    several letters. A pair missing from ``pw`` (its difference constant, not tested)
    counts as different when its difference is not 0.

    Parameters
    ----------
    levels : list
        In display order (letters are given in this order: ``a`` to the first level's
        group).
    pw : DataFrame
        ``A``, ``B`` and the p column ``p``.
    alpha : float

    Returns
    -------
    dict
        level → letters (e.g. ``"ab"``), one character each (:data:`LETTERS`).

    Raises
    ------
    ValueError
        The pattern needs more letters than :data:`LETTERS` holds (76; many levels with
        an irregular pattern of differences): read the pairwise table instead.

    Examples
    --------
    >>> import pandas as pd
    >>> pw = pd.DataFrame({"A": ["x", "x", "y"], "B": ["y", "z", "z"],
    ...                    "p_corr": [0.20, 0.01, 0.30]})
    >>> compact_letters(["x", "y", "z"], pw)
    {'x': 'a', 'y': 'ab', 'z': 'b'}
    """
    groups = letter_groups(levels, pw, alpha, p)
    if len(groups) > len(LETTERS):
        raise ValueError(f"these {len(levels)} levels need {len(groups)} letters, more than "
                         f"the {len(LETTERS)} a compact letter display has: read the pairwise "
                         "table instead")
    letters = {lv: "" for lv in levels}
    for ch, g in zip(LETTERS, groups, strict=False):  # checked above: enough letters
        for lv in g:
            letters[lv] += ch
    return letters


def rating_oneway(data: pd.DataFrame, dv: str = "rating", within: str = "sample",
                  subject: str = SUBJECT, alpha: float = 0.05,
                  missing: str = "listwise") -> dict:
    """One-way repeated-measures analysis of ratings over the levels of ``within``.

    Per-level means with CIs (raw and z-scored per subject), per-subject averages, all
    pairwise paired t-tests (Holm and Benjamini–Hochberg), a compact letter display,
    a one-way RM ANOVA, and session length against power from these data's variances.

    Returns
    -------
    dict
        ``samples`` (list of dicts: level, n, mean, ci_low, ci_high, mean_z, letters, …),
        ``pairwise``, ``anova`` (DataFrames), ``letters`` (compact letter display,
        :func:`compact_letters`, on Holm p), ``groups`` (the levels of each letter),
        ``missing`` and ``excluded_subjects`` (the t-tests' policy and whom it left out;
        listwise, as the ANOVA, unless ``missing = "pairwise"``), ``per_subject``, ``preflight``,
        ``constant_pairs``, ``n_subjects``, ``n_levels``, ``repetitions`` (median per
        subject and level), ``session_length``.
    """
    d = _rated(data, dv)
    absent = not_analysed(participants_of(data, subject), data[subject].astype(str),
                          d[subject].astype(str), "this phase")
    d["rating_z"] = zscore_by_subject(d, dv, subject)
    subj = d.groupby([subject, within], observed=True)[[dv, "rating_z"]].mean()
    samples = []
    for s, g in subj.groupby(level=within, observed=True):
        m, lo, hi = mean_ci(g[dv].to_numpy(), alpha)
        mz, loz, hiz = mean_ci(g["rating_z"].to_numpy(), alpha)
        samples.append({"sample": s, "n": int(len(g)), "mean": m, "ci_low": lo, "ci_high": hi,
                        "mean_z": mz, "ci_low_z": loz, "ci_high_z": hiz})
    samples.sort(key=lambda r: -r["mean"])
    order = [r["sample"] for r in samples]
    d[within] = pd.Categorical(d[within], categories=order, ordered=True)
    d = d.sort_values(within)
    pre = preflight(d, dv, within, subject, scale="scale" if "scale" in d else None)
    if absent:
        pre = pd.concat([pd.DataFrame(absent), pre], ignore_index=True)
    holm = pairwise_ttests(d, dv, within, subject, "holm", alpha, missing)
    fdr = pairwise_ttests(d, dv, within, subject, "fdr_bh", alpha, missing)
    pw = holm.rename(columns={"p_corr": "p_holm"}).drop(columns="p_adjust")
    pw["p_fdr"] = fdr["p_corr"].to_numpy()
    pw["p_corr"] = pw["p_holm"]
    cis = [dz_ci(float(z), int(k), alpha) for z, k in zip(pw["dz"], pw["n"], strict=True)]
    pw["dz_ci_low"] = [c[0] for c in cis]
    pw["dz_ci_high"] = [c[1] for c in cis]
    # the rank-based companions for ordinal ratings (report says where they agree)
    try:
        wx = pairwise_wilcoxon(d, dv, within, subject, "holm")
        ordinal = {"friedman": friedman(d, dv, within, subject), "wilcoxon": wx,
                   "wilcoxon_floor": wx.attrs["p_floor"]}
    except StatsError as exc:
        ordinal = f"not computed: {exc}"
    models = {}  # trial-level models: keep participants with missing cells
    for name, fn in (("mixed", mixed_oneway), ("ordinal", ordinal_mixed)):
        try:
            models[name] = fn(d, dv, within, subject)
        except StatsError as exc:
            models[name] = f"not computed: {exc}"
    groups_present = sorted(g for g in d.get("group", pd.Series(dtype=str)).dropna().astype(str)
                            .unique() if g)
    if len(groups_present) >= 2:  # a between-subject factor (e.g. expert / novice)
        grouped = d[d["group"].fillna("").astype(str) != ""]  # no group is not a group
        try:
            models["mixed_group"] = mixed_oneway(grouped, dv, within, subject, between="group")
        except StatsError as exc:
            models["mixed_group"] = f"not computed: {exc}"
    estimates = {name: {k: m.attrs[k] for k in ("fixed", "thresholds") if k in m.attrs}
                 for name, m in models.items() if not isinstance(m, str)}
    anova = rm_anova(d, dv, within, subject)
    per_subject = (d.groupby([subject, within], observed=True)[dv].mean()
                   .unstack(within).reset_index())
    reps = int(d.groupby([subject, within], observed=True).size().median())
    k = len(order)
    length = None
    try:
        vc = variance_components(d, dv, within, subject)
        length = {"variance_components": vc, "effect": 1.0,
                  "table": power_table(range(5, 31, 5), range(1, 6), effect=1.0, alpha=alpha,
                                       comparisons=k * (k - 1) // 2, seed=0, **vc)}
    except ValueError as exc:
        length = f"not computed: {exc}"
    try:
        letters = compact_letters(order, holm, alpha)
        groups: list | str = letter_groups(order, holm, alpha)
    except ValueError as exc:  # a display beyond 76 letters: said, not drawn
        letters = {lv: "see the pairwise table" for lv in order}
        groups = f"not shown: {exc}"
    for r in samples:
        r["letters"] = letters[r["sample"]]
    return {"samples": samples, "pairwise": pw, "anova": anova, "session_length": length,
            "groups": groups, "letters": letters, "missing": missing, "ordinal": ordinal,
            "models": models, "model_estimates": estimates,
            "excluded_subjects": holm.attrs.get("excluded_subjects", []),
            "per_subject": per_subject,
            "preflight": pre, "constant_pairs": holm.attrs.get("constant_pairs", []),
            "n_subjects": int(d[subject].nunique()), "n_levels": k, "repetitions": reps}


def rating_factorial(data: pd.DataFrame, factors: list[str], by: str | None = None,
                     normalize: str = "zscore", dv: str = "rating",
                     subject: str = SUBJECT) -> dict:
    """Crossed within-subject design: an RM ANOVA over ``factors`` (per ``by`` group when
    given), on ratings z-scored within each subject when ``normalize == "zscore"``, or
    within each subject and block when ``"zscore_block"``.

    Every participant the analysis answers for (:func:`participants_of`) who is not in a
    group's ANOVA is listed in that group's ``preflight`` under the first reason that
    applies: never reached the block, reached it without a valid rating, a set missing
    (listwise), every set rated the same (no z-scores).

    Returns
    -------
    dict
        group (a block, or ``all``) → ``anova``, ``most_significant`` (the main effect with
        the smallest p), ``most_significant_p``, ``main_effects`` (DataFrame: factor, each
        level's mean, the preferred level, p_unc), ``best_set``, ``sets`` (DataFrame: each
        set's mean and count), ``preflight`` (the exclusions, each participant once),
        ``n_subjects`` (in the ANOVA), ``n_selected`` (answered for: ``n_subjects`` plus
        those excluded).
    """
    everyone = participants_of(data, subject)
    d = _rated(data, dv)
    y = dv
    if normalize == "zscore":
        d["rating_z"] = zscore_by_subject(d, dv, subject)
        y = "rating_z"
    elif normalize == "zscore_block":  # per participant and block (material), as the paper
        key = d[subject].astype(str) + "\x1f" + d["block"].astype(str)
        d["rating_z"] = zscore_by_subject(d.assign(_sb=key), dv, "_sb").to_numpy()
        y = "rating_z"
    if y == "rating_z":  # rows whose normalisation unit has no spread
        unit = [subject, "block"] if normalize == "zscore_block" else [subject]
        rng = d.groupby(unit, observed=True)[dv].transform("max") - \
            d.groupby(unit, observed=True)[dv].transform("min")
        d["_flat"] = (rng <= 0).to_numpy()
    by_col = {"block": "block"}.get(by or "", None)
    out = {}
    groups = d.groupby(by_col, observed=True) if by_col else [("all", d)]
    for name, g in groups:
        scope = data[data[by_col].astype(str) == str(name)] if by_col else data
        where = "this block" if by_col else "this phase"
        absent = not_analysed(everyone, scope[subject].astype(str), g[subject].astype(str),
                              where)
        # a set missing first: 'rated every set the same' would be false of who rated two
        cells = g.drop_duplicates([subject, *factors]).groupby(subject, observed=True).size()
        n_cells = len(g.drop_duplicates(list(factors)))
        incomplete = {str(s) for s, k in cells.items() if k < n_cells}
        constant: list[str] = []
        if y == "rating_z":  # z is 0/0 for a participant who rated every set the same
            flat = g["_flat"].to_numpy(bool)
            constant = sorted({str(s) for s in g.loc[flat, subject]} - incomplete)
            g = g[~g[subject].astype(str).isin(constant)]
        anova = rm_anova(g, y, list(factors), subject)
        mains = anova[anova["Source"].isin(factors)]
        most = mains.sort_values(["p_unc", "F"], ascending=[True, False]).iloc[0]
        means = (g.groupby(["sample", *factors], observed=True)[y]
                 .agg(["mean", "count"]).reset_index().sort_values("mean", ascending=False))
        best = means.iloc[0]
        p_of = mains.set_index("Source")["p_unc"]
        effects = []
        for f in factors:
            lv = g.groupby([subject, f], observed=True)[y].mean().unstack(f)
            level_means = {str(c): float(lv[c].mean()) for c in lv.columns}
            effects.append({"factor": f, "level_means": level_means,
                            "preferred": max(level_means, key=level_means.get),
                            "p_unc": float(p_of[f])})
        if all(set(e["level_means"]) == {"low", "high"} for e in effects):
            for e in effects:  # the two-level design of the papers reads low/high
                lo, hi = e["level_means"]["low"], e["level_means"]["high"]
                e.update(mean_z_low=lo, mean_z_high=hi, difference=hi - lo)
        out[str(name)] = {
            "anova": anova, "most_significant": str(most["Source"]),
            "main_effects": pd.DataFrame(effects),
            "most_significant_p": float(most["p_unc"]),
            "best_set": {"sample": str(best["sample"]), "mean": float(best["mean"]),
                         **{f: str(best[f]) for f in factors}},
            "cell_means": (g.groupby([subject, *factors], observed=True)[y].mean()
                           .reset_index().rename(columns={y: "value", subject: "participant"})),
            "sets": means,
            "preflight": _with_constant(pd.concat([pd.DataFrame(absent), preflight(
                g, y, list(factors), subject)], ignore_index=True) if absent else preflight(
                g, y, list(factors), subject), constant, dv, name),
            "n_subjects": int(g[subject].nunique()) - len(incomplete),
            "n_selected": len(everyone),
            "simple_effects": simple_effects(g, y, list(factors), subject, anova)}
    return out


def _each_once(pre: pd.DataFrame) -> pd.DataFrame:
    """The exclusions with each participant under the first reason that applies: a
    participant already left out (never reached, no valid rating, a cell missing) is not
    named again by a later check of the same table (a row left with nobody goes)."""
    if pre.empty:
        return pre
    gone: set[str] = set()
    keep, rows = [], pre.to_dict(orient="records")
    for r in rows:
        who = [s for s in str(r.get("subjects_excluded") or "").split(",") if s]
        if who:
            left = [s for s in who if s not in gone]
            if not left:
                continue
            if len(left) < len(who):
                detail = str(r["detail"])
                if detail.startswith(f"{len(who)} "):  # its count, as the row now stands
                    detail = f"{len(left)}{detail[len(str(len(who))):]}"
                r = {**r, "subjects_excluded": ",".join(left), "n_excluded": len(left),
                     "detail": detail}
            if r["check"] in ("never_reached", "no_valid_rating", "missing_cells"):
                gone.update(left)
        keep.append(r)
    return pd.DataFrame(keep, columns=pre.columns)


def _with_constant(pre: pd.DataFrame, constant: list[str], dv: str, group) -> pd.DataFrame:
    """The preflight table with a row for participants left out because their ratings in
    the normalisation unit were all the same (their z-scores are undefined)."""
    pre = _each_once(pre)
    if not constant:
        return pre
    where = "this block" if group != "all" else "this phase"
    row = {"check": "constant_ratings",
           "detail": f"{len(constant)} participant(s) gave every set in {where} the same {dv}",
           "policy": "excluded from this ANOVA: a z-score with SD 0 is undefined, and "
                     "counting it as 0 would pull every effect toward 0",
           "subjects_excluded": ",".join(constant), "n_excluded": len(constant)}
    return pd.concat([pre, pd.DataFrame([row])], ignore_index=True)


def simple_effects(data: pd.DataFrame, dv: str, factors: list[str], subject: str,
                   anova: pd.DataFrame, alpha: float = 0.05) -> pd.DataFrame:
    """Follow-ups of every significant two-way interaction: the effect of each factor at
    each level of the other (one-way repeated-measures ANOVAs on cell means averaged over
    the remaining factors), Holm-adjusted over the whole family.

    Returns
    -------
    DataFrame
        ``interaction``, ``effect`` (the factor tested), ``at`` (``factor=level``), ``F``,
        ``DF``, ``DF_err``, ``p_unc``, ``p_holm``, ``np2``; empty when no two-way
        interaction has p < alpha.
    """
    rows = []
    for r in anova.itertuples():
        parts = str(r.Source).split(" * ")
        if len(parts) != 2 or r.p_unc >= alpha:
            continue
        for f, other in (parts, parts[::-1]):
            for level, sub in data.groupby(other, observed=True):
                try:
                    a = rm_anova(sub, dv, f, subject).iloc[0]
                except StatsError:
                    continue
                rows.append({"interaction": r.Source, "effect": f, "at": f"{other}={level}",
                             "F": float(a["F"]), "DF": int(a["DF"]), "DF_err": int(a["DF_err"]),
                             "p_unc": float(a["p_unc"]), "np2": float(a["np2"])})
    out = pd.DataFrame(rows, columns=["interaction", "effect", "at", "F", "DF", "DF_err",
                                      "p_unc", "np2"])
    out.insert(7, "p_holm", p_adjust(out["p_unc"].to_numpy(), "holm"))
    return out


def choice_scores(data: pd.DataFrame, levels: list[str] | None = None,
                  subject: str = SUBJECT) -> dict:
    """Paired comparisons (a ``comparison`` phase): for each pair of samples, which was
    chosen (both orders pooled; exact binomial test against 1/2, Holm over the pairs); for
    each sample, the share of its comparisons it won; and the bias towards the sample felt
    first.

    Parameters
    ----------
    data : DataFrame
        The phase's rows (:func:`analysis.load_sessions`): ``sample`` holds the pair as
        felt (``first+second``), ``answer`` the sample chosen.
    levels : list of str, optional
        The phase's samples in the protocol's order (the pairs are written in it).

    Returns
    -------
    dict
        ``pairs`` (:func:`analysis.stats.pair_preferences`), ``samples`` (per sample:
        ``wins``, ``n``, ``prop_won``, best first), ``order``
        (:func:`analysis.stats.order_bias`), ``n_subjects`` and ``n_choices``;
        ``exclusions`` (each participant the analysis answers for, :func:`participants_of`,
        who made no valid choice: never reached the phase, or none valid) and
        ``n_selected`` (``n_subjects`` plus those excluded).
    """
    everyone = participants_of(data, subject)
    d = data[data["valid"]].copy()
    if d.empty:
        raise StatsError("no valid choices")
    felt = d["sample"].str.split("+", expand=True)
    if felt.shape[1] != 2 or felt.isna().any().any():
        raise StatsError("a comparison trial felt two samples; some rows name another count")
    d["first"], d["second"] = felt[0], felt[1]
    pairs = pair_preferences(d, "first", "second", "answer", levels=levels)
    order = order_bias(d, "first", "second", "answer")
    names = list(levels) if levels is not None else list(
        dict.fromkeys([*d["first"], *d["second"]]))
    samples = []
    for s in names:
        n = int(((d["first"] == s) | (d["second"] == s)).sum())
        if n:
            wins = int((d["answer"] == s).sum())
            samples.append({"sample": s, "wins": wins, "n": n, "prop_won": wins / n})
    samples.sort(key=lambda r: -r["prop_won"])
    return {"pairs": pairs, "samples": samples, "order": order,
            "n_subjects": int(d[subject].nunique()), "n_choices": int(len(d)),
            **_left_out(everyone, data, d, subject, "choice")}


def _left_out(everyone: list[str], data: pd.DataFrame, valid: pd.DataFrame, subject: str,
              what: str) -> dict:
    """``exclusions`` (:func:`not_analysed` in this phase) and ``n_selected`` of an analysis
    whose every participant with a valid row is in it."""
    return {"exclusions": not_analysed(everyone, data[subject].astype(str),
                                       valid[subject].astype(str), "this phase", what),
            "n_selected": len(everyone)}


def answer_scores(data: pd.DataFrame, scoring: str = "all_correct",
                  subject: str = SUBJECT) -> dict:
    """Identification answers: percent correct overall, per repetition and group, chance
    level, and a confusion matrix.

    ``scoring = "all_correct"``: a repetition is correct only when every surface is named
    right (chance 1/k! for k surfaces); ``per_surface``: each surface counts on its own
    (chance 1/k).

    ``exclusions`` lists each participant the analysis answers for
    (:func:`participants_of`) who gave no valid answer (never reached the phase, or none
    valid); ``n_selected`` is ``n_subjects`` plus those.
    """
    everyone = participants_of(data, subject)
    d = data[data["valid"]].copy()
    if d.empty:
        raise StatsError("no valid identification answers")
    d["truth"] = d["sample"].str.replace("+", ",", regex=False)
    k = int(d["truth"].str.count(",").max()) + 1
    if scoring == "per_surface":
        rows = []
        for r in d.itertuples():
            for t, a in zip(r.truth.split(","), str(r.answer).split(","), strict=False):
                rows.append({subject: getattr(r, subject), "correct": int(t == a),
                             "repetition": r.repetition, "group": r.group,
                             "answer": a, "truth": t})
        scored = pd.DataFrame(rows)
        chance = 1 / k
    else:
        scored = d
        chance = 1 / math.factorial(k)
    res = identification_scores(scored, subject, "correct", repetition="repetition",
                                group="group", chance=chance, answer="answer", truth="truth")
    try:
        per_person = participant_identification_test(scored, subject, "correct", chance,
                                                     group="group")
    except StatsError as exc:
        per_person = f"not computed: {exc}"
    return {"table": res["summary"], "confusion": res.get("confusion"), "chance": chance,
            "surfaces": k, "scoring": scoring, "n_subjects": int(d[subject].nunique()),
            "per_participant": per_person,
            "groups_compared": None if isinstance(per_person, str) else
            per_person.attrs.get("groups"),
            **_left_out(everyone, data, d, subject, "answer")}


def device_summary(data: pd.DataFrame, subject: str = SUBJECT) -> dict:
    """Incoming speeds over the valid taps of ``data``; saturations per participant (mean and
    range) and per sample."""
    valid = data[data["valid"]]
    v = tap_velocities(valid)
    sat = data[data["status"].isin(["saturated", "excluded_saturated"])]
    per_p = sat.groupby(subject).size().reindex(data[subject].unique(), fill_value=0)
    return {"velocity_mean": float(v.mean()) if v.size else None,
            "velocity_sd": float(v.std(ddof=1)) if v.size > 1 else None,
            "n_taps": int(v.size),
            "saturations_per_participant": {
                "mean": float(per_p.mean()) if len(per_p) else None,
                "min": int(per_p.min()) if len(per_p) else None,
                "max": int(per_p.max()) if len(per_p) else None,
                "by_participant": {str(k): int(x) for k, x in per_p.items()}},
            "saturations_per_sample": {str(k): int(x) for k, x in
                                       sat.groupby("sample").size().items()}}
