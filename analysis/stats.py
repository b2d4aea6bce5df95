"""Statistics in the manner of pingouin: long-format DataFrame and column names in, tidy table out.

Every function works on per-subject cell means (repeated ratings of a cell are averaged
first), refuses to compute on data it cannot analyse honestly (see :func:`preflight`), and
returns tables without NaN or infinity.
"""

from __future__ import annotations

import itertools
import math
import numbers
import re
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pandas as pd
from scipy import special, stats

__all__ = ["preflight", "zscore_by_subject", "pairwise_ttests", "rm_anova",
           "identification_scores", "cell_means", "wide_means", "p_adjust", "StatsError",
           "friedman", "pairwise_wilcoxon", "dz_ci", "participant_identification_test",
           "mixed_oneway", "np2_ci", "signed_rank_test", "tie_groups", "equivalence_ttests"]

PADJUST = ("none", "bonf", "holm", "fdr_bh")
#: Values closer than this fraction of the data's spread (largest minus smallest) are
#: equal: floating-point averaging (7/3 − 4/3 = 0.9999999999999998, 7/3 − 2 ≠ 2 − 5/3) must
#: not become an effect of 1e16 SDs, nor break a tie between ranks. Relative to the spread,
#: not the magnitude, so that shifting every rating by a constant changes nothing.
RTOL = 1e-9
MISSING = ("listwise", "pairwise")


class StatsError(ValueError):
    """The data cannot be analysed as asked (the message says why and what to do)."""


def _as_list(within: str | Sequence[str]) -> list[str]:
    return [within] if isinstance(within, str) else list(within)


def _check_columns(data: pd.DataFrame, cols: Sequence[str]) -> None:
    missing = [c for c in cols if c not in data.columns]
    if missing:
        raise StatsError(f"columns not in the data: {missing}; it has {list(data.columns)}")


def _rows(mask: pd.Series, limit: int = 8) -> str:
    """The index labels where ``mask`` holds, as a short list for an error message."""
    idx = list(mask[mask].index)
    more = f" and {len(idx) - limit} more" if len(idx) > limit else ""
    return ", ".join(map(str, idx[:limit])) + more


def _check_values(data: pd.DataFrame, dv: str, labels: Sequence[str]) -> None:
    """Refuse missing labels and non-finite values, naming the column and the rows.

    A missing ``dv`` (NaN, empty) is allowed: it is dropped and listed by preflight. An
    infinite one is refused: it is a recording or typing error, not a rating.
    """
    for c in labels:
        bad = data[c].isna()
        if bad.any():
            raise StatsError(f"column {c!r} has no label in rows {_rows(bad)}: name the "
                             f"{c} of every row, or drop those rows")
    col = data[dv]
    v = (col.astype(float) if pd.api.types.is_numeric_dtype(col)
         else pd.to_numeric(col, errors="coerce"))
    bad = np.isinf(v.to_numpy(float))
    if bad.any():
        raise StatsError(f"column {dv!r} is not finite in rows "
                         f"{_rows(pd.Series(bad, index=data.index))}: a value of ±inf is not "
                         "a measurement; correct or drop those rows")


def _tol(values: np.ndarray) -> float:
    """Absolute tolerance for 'equal' among ``values``: RTOL × their spread (max − min)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return RTOL * float(v.max() - v.min()) if v.size else 0.0


def _anchor(v: np.ndarray) -> float:
    """A value of the data near its middle, to subtract before averaging.

    Ratings are integers, so subtracting one of them is exact; averages of the remainders
    then carry no rounding from the ratings' offset (a 1e12 shift leaves the cell means'
    differences as they were).
    """
    v = np.asarray(v, float)
    v = np.sort(v[np.isfinite(v)])
    return float(v[v.size // 2]) if v.size else 0.0


def tie_groups(x: np.ndarray, tol: float) -> np.ndarray:
    """``x`` with each run of values closer than ``tol`` (in sorted order) replaced by the
    run's smallest value, so that rank-based statistics see ties where the data are tied.

    Cell means of integer ratings are fractions whose doubles differ in the last bit when
    computed different ways (7/3 − 2 and 2 − 5/3); ``tol`` (:data:`RTOL` × the spread) is
    far below the smallest real difference between such means.

    Examples
    --------
    >>> from analysis.stats import tie_groups
    >>> x = np.array([7 / 3 - 2, 2 - 5 / 3, 0.5])
    >>> bool(x[0] == x[1]), bool(tie_groups(x, 1e-9)[0] == tie_groups(x, 1e-9)[1])
    (False, True)
    """
    x = np.asarray(x, float)
    if x.size < 2:
        return x.copy()
    order = np.argsort(x, kind="stable")
    xs = x[order]
    first = np.concatenate([[True], np.diff(xs) > tol])
    out = np.empty_like(x)
    out[order] = xs[first][np.cumsum(first) - 1]
    return out


def wide_means(data: pd.DataFrame, dv: str, within: str, subject: str,
               centred: bool = False) -> tuple[np.ndarray, list, list]:
    """Subject × level matrix of mean ``dv`` (NaN where a subject lacks a level).

    Built with one factorisation and two bincounts, in order of first appearance: the
    fast path of the one-factor analyses (pandas' groupby and pivot cost ~10× more).
    With ``centred``, a value of the data near its middle is subtracted before averaging
    (:func:`_anchor`): for callers that use only differences or ranks of the means, which
    then do not depend on the ratings' offset.

    Returns
    -------
    (matrix, subjects, levels)
    """
    _check_columns(data, [dv, within, subject])
    _check_values(data, dv, [within, subject])
    col = data[dv]
    v = (col.to_numpy(float) if pd.api.types.is_numeric_dtype(col)
         else pd.to_numeric(col, errors="coerce").to_numpy(float))
    keep = ~np.isnan(v)
    si, subjects = pd.factorize(data[subject])  # on the Series: no conversion of its strings
    li, levels = pd.factorize(data[within])
    if not keep.all():  # drop missing values, and levels or subjects left with none
        si, li, v = si[keep], li[keep], v[keep]
        used_s, si = np.unique(si, return_inverse=True)
        used, li = np.unique(li, return_inverse=True)
        subjects = pd.Index(np.asarray(subjects)[used_s])  # labels in the rows' code order
        levels = pd.Index(np.asarray(levels)[used])
    else:
        v = v[keep]
    if centred:
        v = v - _anchor(v)
    ns, nl = len(subjects), len(levels)
    idx = si * nl + li
    sums = np.bincount(idx, weights=v, minlength=ns * nl)
    counts = np.bincount(idx, minlength=ns * nl)
    with np.errstate(invalid="ignore", divide="ignore"):
        m = (sums / counts).reshape(ns, nl)
    return m, list(subjects), list(levels)


def cell_means(data: pd.DataFrame, dv: str, within: str | Sequence[str], subject: str
               ) -> pd.DataFrame:
    """Mean of ``dv`` per subject and within-cell (long format, one row per cell)."""
    w = _as_list(within)
    _check_columns(data, [dv, subject, *w])
    return (data.groupby([subject, *w], observed=True, sort=True)[dv].mean()
            .reset_index())


# --------------------------------------------------------------------- preflight
def preflight(data: pd.DataFrame, dv: str, within: str | Sequence[str], subject: str,
              scale: str | None = None) -> pd.DataFrame:
    """Check data for the analyses below; one row per problem found.

    Parameters
    ----------
    data : DataFrame (long format)
    dv, within, subject : column names
    scale : str, optional
        Column naming each row's rating scale (e.g. "1-7"); more than one value is flagged.

    Returns
    -------
    DataFrame
        ``check`` (missing_cells, nan, zero_variance, constant_differences, too_few_subjects,
        duplicate_rows, mixed_scales), ``detail``, ``policy`` (what the analyses do about it),
        ``subjects_excluded`` (comma-separated), ``n_excluded``. Empty when all is well.

    Notes
    -----
    A pair's differences are "constant" when their SD is 0: the t statistic is then
    undefined (a difference with no spread), and the pair is listed rather than tested.

    Examples
    --------
    >>> import analysis as A
    >>> df = A.datasets.read_dataset("ratings")
    >>> A.preflight(df, "rating", "sample", "participant").empty
    True
    >>> A.preflight(df[~((df.participant == "P02") & (df["sample"] == "wood"))],
    ...             "rating", "sample", "participant")[["check", "n_excluded"]]
               check  n_excluded
    0  missing_cells           1
    """
    w = _as_list(within)
    _check_columns(data, [dv, subject, *w] + ([scale] if scale else []))
    rows = []

    def add(check, detail, policy, excluded=()):
        ex = sorted({str(s) for s in excluded})
        rows.append({"check": check, "detail": detail, "policy": policy,
                     "subjects_excluded": ",".join(ex), "n_excluded": len(ex)})

    vals = pd.to_numeric(data[dv], errors="coerce")
    nan = data[vals.isna()]
    if len(nan):
        add("nan", f"{len(nan)} rows without a numeric {dv}",
            "rows dropped before averaging cells", ())
    dup = data[data.duplicated(keep="first")]
    if len(dup):
        add("duplicate_rows", f"{len(dup)} identical rows",
            "kept: identical repeated ratings are averaged within their cell", ())
    clean = data[vals.notna()].assign(**{dv: vals[vals.notna()]})
    cells = clean.groupby(w, observed=True).size().index
    n_cells = len(cells)
    per_subject = clean.groupby(subject, observed=True).apply(
        lambda g: g.groupby(w, observed=True).ngroups, include_groups=False)
    incomplete = per_subject[per_subject < n_cells]
    if len(incomplete):
        add("missing_cells", "; ".join(f"{s}: {n_cells - k} of {n_cells} cells missing"
                                       for s, k in incomplete.items()),
            "subjects excluded from repeated-measures tests (listwise)", incomplete.index)
    sd = clean.groupby(subject, observed=True)[dv].std(ddof=0)
    zero = sd[sd == 0]
    if len(zero):
        add("zero_variance", f"{len(zero)} subject(s) gave the same {dv} everywhere",
            "their z-scores are 0 (stated case); kept in raw analyses", zero.index)
    n_subj = clean[subject].nunique() - len(incomplete)
    if n_subj < 2:
        add("too_few_subjects", f"{n_subj} complete subject(s)",
            "no test is computed (needs n >= 2)", ())
    if n_cells >= 2 and len(w) == 1 and n_subj >= 2:
        cm = cell_means(clean[~clean[subject].isin(incomplete.index)], dv, w, subject)
        wide = cm.pivot(index=subject, columns=w[0], values=dv)
        tol = _tol(wide.to_numpy())
        for a, b in itertools.combinations(wide.columns, 2):
            d = (wide[a] - wide[b]).dropna()
            if len(d) >= 2 and d.std(ddof=1) <= tol:
                m = float(d.mean()) if abs(d.mean()) > tol else 0.0
                add("constant_differences", f"{a} − {b} is {m:.6g} for every subject",
                    "pair reported without t, p or d_z (undefined); listed here", ())
    if scale:
        scales = clean[scale].dropna().unique()
        if len(scales) > 1:
            add("mixed_scales", f"{dv} comes on scales {sorted(map(str, scales))}",
                "refused: z-score per subject first, or analyse the scales apart", ())
    return pd.DataFrame(rows, columns=["check", "detail", "policy", "subjects_excluded",
                                       "n_excluded"])


def _complete(data, dv, within, subject) -> pd.DataFrame:
    """Cell means of subjects with every cell, NaN rows dropped."""
    w = _as_list(within)
    _check_values(data, dv, [*w, subject])
    vals = pd.to_numeric(data[dv], errors="coerce")
    clean = data[vals.notna()].assign(**{dv: vals[vals.notna()]})
    clean[dv] = clean[dv] - _anchor(clean[dv].to_numpy(float))  # differences only: exact
    cm = cell_means(clean, dv, w, subject)
    n_cells = cm.groupby(w, observed=True).ngroups
    counts = cm.groupby(subject, observed=True).size()
    keep = counts[counts == n_cells].index
    return cm[cm[subject].isin(keep)]


# --------------------------------------------------------------------- z-scores
def zscore_by_subject(data: pd.DataFrame, dv: str, subject: str) -> pd.Series:
    """``dv`` normalised within each subject to mean 0 and SD 1 (the SD with divisor n,
    ddof = 0).

    A subject who gave the same value everywhere has SD 0: their z-scores are 0 — they
    used no part of the scale to prefer anything — rather than NaN.

    Returns
    -------
    Series aligned with ``data`` (name ``<dv>_z``).

    Notes
    -----
    z = (x − mean_subject) / SD_subject with the population SD (ddof = 0), as the
    reality-based models study normalised each subject's ratings to mean 0 and SD 1.

    Examples
    --------
    >>> import analysis as A
    >>> df = A.datasets.read_dataset("ratings")
    >>> z = A.zscore_by_subject(df, "rating", "participant")
    >>> z.groupby(df["participant"]).std(ddof=0).round(6).unique().tolist()
    [1.0]
    """
    _check_columns(data, [dv, subject])
    _check_values(data, dv, [subject])
    v = pd.to_numeric(data[dv], errors="coerce")
    v = v - v.groupby(data[subject], observed=True).transform("min")  # exact for ratings
    g = v.groupby(data[subject], observed=True)
    mean = g.transform("mean")
    sd = g.transform(lambda x: x.std(ddof=0))
    z = (v - mean) / sd.where(sd > 0, 1.0)
    z = z.where(sd > 0, 0.0).where(v.notna())
    return z.rename(f"{dv}_z")


# --------------------------------------------------------------------- t-tests
def p_adjust(p: np.ndarray, method: str) -> np.ndarray:
    """Adjust p-values: none, bonf (Bonferroni), holm (Holm–Bonferroni), fdr_bh
    (Benjamini–Hochberg).

    Notes
    -----
    Holm: with p sorted ascending, p̃₍ᵢ₎ = max_{j ≤ i} min(1, (m − j + 1)·p₍ⱼ₎).
    Benjamini–Hochberg: p̃₍ᵢ₎ = min_{j ≥ i} min(1, m·p₍ⱼ₎ / j).

    Examples
    --------
    >>> from analysis import p_adjust
    >>> p_adjust([0.01, 0.04, 0.03], "holm").round(3).tolist()
    [0.03, 0.06, 0.06]
    >>> p_adjust([0.01, 0.04, 0.03], "fdr_bh").round(3).tolist()
    [0.03, 0.04, 0.04]
    """
    p = np.asarray(p, float)
    m = p.size
    if method not in PADJUST:
        raise StatsError(f"padjust must be one of {', '.join(PADJUST)}, got {method!r}")
    if m == 0 or method == "none":
        return p.copy()
    if method == "bonf":
        return np.minimum(1.0, p * m)
    order = np.argsort(p)
    ps = p[order]
    if method == "holm":
        adj = np.maximum.accumulate((m - np.arange(m)) * ps)
    else:  # fdr_bh
        adj = np.minimum.accumulate(m / np.arange(m, 0, -1) * ps[::-1])[::-1]
    out = np.empty(m)
    out[order] = np.minimum(1.0, adj)
    return out


def pairwise_ttests(data: pd.DataFrame, dv: str, within: str, subject: str,
                    padjust: str = "holm", alpha: float = 0.05,
                    missing: str = "listwise") -> pd.DataFrame:
    """Paired t-tests between every pair of levels of ``within``, on per-subject means.

    ``missing = "listwise"`` (the default, as pingouin and JASP, and as :func:`rm_anova`):
    subjects missing any level are left out of every pair, and listed in
    ``result.attrs["excluded_subjects"]``; ``"pairwise"``: they are dropped only from the
    pairs involving the level they lack. A pair whose differences are the same for every
    subject (within ``RTOL`` of the data's magnitude) has no t, p or d_z; it is left out
    of the table and listed in ``result.attrs["constant_pairs"]`` (and by
    :func:`preflight`). A mean difference within that tolerance of 0 is reported as 0.

    Returns
    -------
    DataFrame, one row per pair (levels in order of first appearance)
        ``A``, ``B``; ``mean_diff`` (mean of A − B); ``ci_low``, ``ci_high`` (its 1 − alpha
        confidence interval, t distribution); ``t``; ``dof`` (n − 1); ``p_unc`` (two-sided);
        ``p_corr`` (adjusted by ``padjust`` over the pairs in the table); ``p_adjust``
        (the method); ``dz`` (Cohen's d_z = mean difference / SD of the differences); ``n``.

    Notes
    -----
    For each pair, d = A − B per subject (cell means), t = mean(d) / (SD(d) / √n) with
    n − 1 degrees of freedom, two-sided p, and the CI mean(d) ± t₁₋α/₂ · SD(d) / √n.

    Examples
    --------
    >>> import analysis as A
    >>> df = A.datasets.read_dataset("ratings")
    >>> pw = A.pairwise_ttests(df, "rating", "sample", "participant", padjust="holm")
    >>> pw[["A", "B", "mean_diff", "t", "dof", "p_corr"]].head(2).round(3)
          A      B  mean_diff      t  dof  p_corr
    0  firm   foam      0.917  4.568    5   0.048
    1  firm  pulse     -0.667 -6.325    5   0.013
    """
    d = _paired_differences(data, dv, within, subject, missing)
    g, levels, n, mean, se = d.good, d.levels, d.n, d.mean, d.se
    q = special.stdtrit(d.dof, 1 - alpha / 2)  # t quantile (scipy.special: no per-call overhead)
    t = mean / se
    p = 2 * special.stdtr(d.dof, -np.abs(t))  # two-sided p
    out = pd.DataFrame({
        "A": [levels[a] for a in d.ia[g]], "B": [levels[b] for b in d.ib[g]],
        "mean_diff": mean[g], "ci_low": (mean - q * se)[g], "ci_high": (mean + q * se)[g],
        "t": t[g], "dof": (n - 1)[g], "p_unc": p[g], "p_corr": p_adjust(p[g], padjust),
        "p_adjust": padjust, "dz": (mean / np.where(g, d.sd, 1.0))[g], "n": n[g]})
    return d.attach(out)


class _Differences(NamedTuple):
    """Per-pair paired differences of per-subject cell means (:func:`_paired_differences`)."""

    levels: list
    ia: np.ndarray
    ib: np.ndarray
    n: np.ndarray
    mean: np.ndarray   # 0 where within the data's tolerance of it
    sd: np.ndarray
    se: np.ndarray     # 1 where the pair has no test (not ``good``)
    dof: np.ndarray
    good: np.ndarray   # at least 2 subjects and differences that vary
    constant: list     # (A, B, why) of the pairs without a test
    missing: str
    excluded: list

    def attach(self, table: pd.DataFrame) -> pd.DataFrame:
        table.attrs["constant_pairs"] = self.constant
        table.attrs["missing"] = self.missing
        table.attrs["excluded_subjects"] = self.excluded if self.missing == "listwise" else []
        return table


def _paired_differences(data: pd.DataFrame, dv: str, within: str, subject: str,
                        missing: str) -> _Differences:
    """Every pair of levels at once: an n × pairs matrix of differences of cell means
    (listwise or pairwise complete), their mean, SD and standard error."""
    if missing not in MISSING:
        raise StatsError(f"missing must be one of {', '.join(MISSING)}, got {missing!r}")
    W, subjects, levels = wide_means(data, dv, within, subject, centred=True)
    gaps = np.isnan(W).any(axis=1)
    excluded = [subjects[i] for i in np.nonzero(gaps)[0]]
    if missing == "listwise":
        W = W[~gaps]
    tol = _tol(W)
    ia, ib = np.triu_indices(len(levels), k=1)
    D = W[:, ia] - W[:, ib]
    ok = ~np.isnan(D)
    n = ok.sum(axis=0)
    nn = np.maximum(n, 1)
    mean = np.where(ok, D, 0.0).sum(axis=0) / nn
    sd = np.sqrt((np.where(ok, D - mean, 0.0) ** 2).sum(axis=0) / np.maximum(n - 1, 1))
    mean = np.where(np.abs(mean) <= tol, 0.0, mean)  # an exact zero is shown as 0
    good = (n >= 2) & (sd > tol)
    constant = [(levels[a], levels[b], "fewer than 2 subjects" if k < 2 else
                 f"difference {m:.6g} for every subject")
                for a, b, k, m, g in zip(ia, ib, n, mean, good, strict=True) if not g]
    se = np.where(good, sd / np.sqrt(nn), 1.0)
    return _Differences(levels, ia, ib, n, mean, sd, se, np.maximum(n - 1, 1), good, constant,
                        missing, excluded)


def equivalence_ttests(data: pd.DataFrame, dv: str, within: str, subject: str, bound: float,
                       pairs: Sequence[tuple[str, str]] | None = None, alpha: float = 0.05,
                       missing: str = "listwise") -> pd.DataFrame:
    """Paired equivalence tests (TOST) between levels of ``within``, on per-subject means.

    A non-significant t-test does not show that two samples are alike (with few subjects
    it is what a real difference gives too); the two one-sided tests do: the mean
    difference is shown to lie within ±``bound`` when both H₀: δ ≤ −bound and
    H₀: δ ≥ +bound are rejected at ``alpha``, i.e. when the 1 − 2·alpha confidence interval
    lies inside (−bound, +bound). Subjects and constant pairs as :func:`pairwise_ttests`.

    Parameters
    ----------
    bound : float
        The equivalence margin, in units of ``dv`` (> 0).
    pairs : sequence of (str, str), optional
        The pairs to test (default: every pair, levels in order of first appearance).

    Returns
    -------
    DataFrame, one row per pair
        ``A``, ``B``; ``mean_diff`` (A − B); ``ci_low``, ``ci_high`` (its 1 − 2·alpha CI);
        ``bound``; ``t_lower`` = (mean_diff + bound)/SE, ``p_lower`` (one-sided, greater);
        ``t_upper`` = (mean_diff − bound)/SE, ``p_upper`` (one-sided, less); ``dof``;
        ``p`` (the larger of the two); ``equivalent`` (p < alpha); ``bound_reached``, the
        smallest margin these data show equivalence within at alpha (the CI's farther end
        from 0); ``n``.

    Notes
    -----
    As R's ``t.test(x, y, paired = TRUE, mu = -bound, alternative = "greater")`` and
    ``mu = bound, alternative = "less"`` (tests/r/reference.R), and pingouin's
    ``tost(x, y, bound, paired=True)``.

    Examples
    --------
    >>> import analysis as A
    >>> df = A.datasets.read_dataset("ratings")
    >>> eq = A.equivalence_ttests(df, "rating", "sample", "participant", bound=1.0,
    ...                           pairs=[("firm", "foam"), ("firm", "pulse")])
    >>> eq[["A", "B", "mean_diff", "ci_low", "ci_high", "p", "equivalent"]].round(3)
          A      B  mean_diff  ci_low  ci_high      p  equivalent
    0  firm   foam      0.917   0.512    1.321  0.348       False
    1  firm  pulse     -0.667  -0.879   -0.454  0.013        True
    """
    if isinstance(bound, bool) or not (isinstance(bound, numbers.Real) and math.isfinite(bound)
                                       and bound > 0):
        raise StatsError(f"bound must be a finite number > 0 (in units of {dv!r}), "
                         f"got {bound!r}")
    d = _paired_differences(data, dv, within, subject, missing)
    forward = [(d.levels[a], d.levels[b]) for a, b in zip(d.ia, d.ib, strict=True)]
    index = {p: (j, 1.0) for j, p in enumerate(forward)}
    index.update({(b, a): (j, -1.0) for j, (a, b) in enumerate(forward)})
    wanted = forward if pairs is None else [tuple(p) for p in pairs]
    unknown = [p for p in wanted if p not in index]
    if unknown:
        raise StatsError(f"no such pair of {within!r} levels: {unknown[0]} (levels: "
                         f"{', '.join(map(str, d.levels))})")
    rows = []
    q = special.stdtrit(d.dof, 1 - alpha)
    for a, b in wanted:
        j, sign = index[(a, b)]
        if not d.good[j]:
            continue  # listed in attrs["constant_pairs"]
        m, se, dof = sign * d.mean[j], d.se[j], d.dof[j]
        lo, hi = m - q[j] * se, m + q[j] * se
        t_lo, t_hi = (m + bound) / se, (m - bound) / se
        p_lo, p_hi = special.stdtr(dof, -t_lo), special.stdtr(dof, t_hi)
        rows.append({"A": a, "B": b, "mean_diff": m, "ci_low": lo, "ci_high": hi,
                     "bound": float(bound), "t_lower": t_lo, "p_lower": p_lo,
                     "t_upper": t_hi, "p_upper": p_hi, "dof": int(d.n[j] - 1),
                     "p": max(p_lo, p_hi), "equivalent": bool(max(p_lo, p_hi) < alpha),
                     "bound_reached": max(abs(lo), abs(hi)), "n": int(d.n[j])})
    cols = ["A", "B", "mean_diff", "ci_low", "ci_high", "bound", "t_lower", "p_lower",
            "t_upper", "p_upper", "dof", "p", "equivalent", "bound_reached", "n"]
    return d.attach(pd.DataFrame(rows, columns=cols))


# --------------------------------------------------------------------- ANOVA
def _effect(arr: np.ndarray, axes: tuple[int, ...]) -> np.ndarray:
    """Interaction contrast of the axes in ``axes`` (others averaged out), balanced data."""
    others = tuple(i for i in range(arr.ndim) if i not in axes)
    m = arr.mean(axis=others, keepdims=True) if others else arr
    m = m - arr.mean()
    for ax in axes:  # remove the lower-order terms by centring along each axis in turn
        m = m - m.mean(axis=ax, keepdims=True)
    return m


def rm_anova(data: pd.DataFrame, dv: str, within: str | Sequence[str], subject: str
             ) -> pd.DataFrame:
    """Repeated-measures ANOVA with one to three within-subject factors (balanced data).

    Subjects lacking any cell are excluded (listwise; :func:`preflight` reports them).
    Each effect is tested against its interaction with subjects.

    Returns
    -------
    DataFrame, one row per effect (main effects, then interactions); every cell is a number
        ``Source``; ``SS`` (sum of squares); ``DF``; ``MS``; ``F``; ``p_unc``; ``np2``
        (partial η² = SS_effect / (SS_effect + SS_error)); ``np2_ci_low``, ``np2_ci_high``
        (its 95 % CI, :func:`np2_ci`); ``ng2`` (generalized η²,
        Olejnik & Algina 2003, all factors manipulated within subjects:
        SS_effect / (SS_effect + SS_subjects + Σ SS_errors)); ``SS_err``, ``DF_err``,
        ``MS_err`` (the effect × subject error term the F is taken against); and, for a
        single factor with more than two levels, ``eps_gg`` (Greenhouse–Geisser ε),
        ``eps_hf`` (Huynh–Feldt ε, at most 1), ``p_gg`` (p with both degrees of freedom ×
        ε_GG) and, when there are more subjects than levels (otherwise the contrast
        covariance is singular and the test undefined), ``W_mauchly`` and ``p_spher``
        (Mauchly's test). ``attrs["notes"]`` lists what was not computed and why.

    Notes
    -----
    With cell means y (subjects × levels), each effect's SS is the sum of squares of its
    interaction contrast (lower-order terms removed), scaled to the full layout; its error
    is the effect × subject SS with (n − 1)·Π(levels − 1) degrees of freedom; F = MS / MS_err.
    ε_GG = tr(S)² / (p · tr(S²)) for the covariance S of p orthonormal contrasts;
    ε_HF = (n·p·ε_GG − 2) / (p·(n − 1 − p·ε_GG)), at most 1.

    Examples
    --------
    >>> import analysis as A
    >>> df = A.datasets.read_dataset("ratings")
    >>> aov = A.rm_anova(df, "rating", "sample", "participant")
    >>> aov[["Source", "DF", "DF_err", "F", "np2", "eps_gg"]].round(3)
       Source  DF  DF_err       F    np2  eps_gg
    0  sample   5      25  56.095  0.918   0.495
    >>> cr = A.datasets.read_dataset("crossed")
    >>> A.rm_anova(cr, "rating", ["spring", "transient"], "participant")[
    ...     ["Source", "DF", "DF_err", "F", "p_unc"]].round(4)
                   Source  DF  DF_err        F   p_unc
    0              spring   1       5  13.7500  0.0139
    1           transient   2      10   9.3733  0.0051
    2  spring * transient   2      10   0.0220  0.9783
    """
    w = _as_list(within)
    if not 1 <= len(w) <= 3:
        raise StatsError(f"rm_anova takes one to three within factors, got {len(w)}")
    _check_columns(data, [dv, subject, *w])
    if len(w) == 1:
        m, subjects, lv = wide_means(data, dv, w[0], subject, centred=True)
        arr = m[~np.isnan(m).any(axis=1)]  # listwise: subjects with every level
        n_subj, levels = arr.shape[0], [lv]
    else:
        cm = _complete(data, dv, w, subject)
        subjects = list(dict.fromkeys(cm[subject]))
        levels = [list(dict.fromkeys(cm[f])) for f in w]
        n_subj = len(subjects)
    if n_subj < 2:
        raise StatsError(f"rm_anova needs at least 2 subjects with every cell, has {n_subj}")
    for f, lv in zip(w, levels, strict=True):
        if len(lv) < 2:
            raise StatsError(f"factor {f!r} has a single level ({lv}); nothing to test")
    shape = (n_subj, *(len(lv) for lv in levels))
    if len(w) > 1:
        arr = np.empty(shape)
        idx = {s: i for i, s in enumerate(subjects)}
        lidx = [{v: i for i, v in enumerate(lv)} for lv in levels]
        for row in cm.itertuples(index=False):
            r = row._asdict()
            arr[(idx[r[subject]], *(li[r[f]] for f, li in zip(w, lidx, strict=True)))] = r[dv]
    n_total = arr.size
    nf = len(w)
    # computed on data centred and scaled to magnitude 1 (F, p, η² and ε do not depend on
    # the units; sums of squares are scaled back), so 1e±150 neither overflows nor
    # underflows; differences within RTOL of the data's magnitude are zero
    centre = float(arr.mean())
    spread = float(np.abs(arr - centre).max())
    if spread <= _tol(arr):  # also all zeros: the tolerance is then 0
        raise StatsError(f"every cell mean of {dv!r} is the same ({centre:.6g}): there is "
                         "no variation, so no effect can be tested (F is undefined)")
    arr = (arr - centre) / spread
    tiny = n_total * RTOL ** 2  # a sum of squares of differences within tolerance

    def ss(axes):
        eff = _effect(arr, axes)
        return float((eff ** 2).sum() * n_total / eff.size)

    ss_subj = ss((0,))
    terms = [c for k in range(1, nf + 1) for c in itertools.combinations(range(1, nf + 1), k)]
    rows = []
    errors = {}
    for t in terms:
        ss_e = ss((0, *t))
        df_e = (n_subj - 1) * math.prod(shape[i] - 1 for i in t)
        errors[t] = (ss_e, df_e)
    total_err = ss_subj + sum(e[0] for e in errors.values())
    notes = []
    for t in terms:
        name = " * ".join(w[i - 1] for i in t)
        ss_t = ss(t)
        df_t = math.prod(shape[i] - 1 for i in t)
        ss_e, df_e = errors[t]
        if ss_t <= tiny:
            ss_t = 0.0
        if ss_e <= tiny:
            raise StatsError(f"no error variance for {name.replace(' * ', ' × ')}: every "
                             "subject shows the same effect (within rounding); the F test is "
                             "undefined — report the effect descriptively")
        ms_t, ms_e = ss_t / df_t, ss_e / df_e
        F = ms_t / ms_e
        row = {"Source": name, "n": n_subj, "SS": ss_t * spread ** 2, "DF": df_t,
               "MS": ms_t * spread ** 2, "F": F,
               "p_unc": float(special.fdtrc(df_t, df_e, F)),
               "np2": ss_t / (ss_t + ss_e), "ng2": ss_t / (ss_t + total_err),
               "SS_err": ss_e * spread ** 2, "DF_err": df_e, "MS_err": ms_e * spread ** 2}
        row["np2_ci_low"], row["np2_ci_high"] = np2_ci(F, df_t, df_e)
        if df_t > 1:  # sphericity: ε and Mauchly's test on the effect's own contrasts
            sph = _sphericity(_contrast_scores(arr, t))
            row.update(sph)
            row["p_gg"] = float(special.fdtrc(df_t * sph["eps_gg"], df_e * sph["eps_gg"], F))
            if "eps_hf" in sph:
                row["p_hf"] = float(special.fdtrc(df_t * sph["eps_hf"], df_e * sph["eps_hf"],
                                                  F))
            else:
                notes.append(f"{name}: Huynh–Feldt ε not computed: its estimate is undefined "
                             f"with {n_subj} subjects for {df_t} contrasts; use the "
                             "Greenhouse–Geisser ε")
            if "W_mauchly" not in sph:
                notes.append(f"{name}: Mauchly's test not computed: {n_subj} subjects give a "
                             f"singular covariance of the {df_t} contrasts (it needs at least "
                             f"{df_t + 1}); use the Greenhouse–Geisser p")
        rows.append(row)
    out = pd.DataFrame(rows)
    if nf == 1:  # the one-way notes need no effect name
        notes = [n.split(": ", 1)[1] for n in notes]
    out.attrs["notes"] = notes
    return out


def _helmert(k: int) -> np.ndarray:
    """k × (k − 1) orthonormal Helmert contrasts."""
    C = np.zeros((k, k - 1))
    for j in range(k - 1):
        C[: j + 1, j] = 1.0
        C[j + 1, j] = -(j + 1)
        C[:, j] /= np.linalg.norm(C[:, j])
    return C


def _contrast_scores(arr: np.ndarray, term: tuple[int, ...]) -> np.ndarray:
    """Subjects × contrasts of effect ``term`` (axes of ``arr``; 0 is subjects): the cell
    means averaged over the other factors, times the Kronecker product of the term's
    orthonormal contrasts."""
    others = tuple(i for i in range(1, arr.ndim) if i not in term)
    m = arr.mean(axis=others) if others else arr
    K = np.ones((1, 1))
    for i in term:
        K = np.kron(K, _helmert(arr.shape[i]))
    return m.reshape(m.shape[0], -1) @ K


def _sphericity(Y: np.ndarray) -> dict[str, float]:
    """Mauchly's W and the Greenhouse–Geisser / Huynh–Feldt epsilons from subjects ×
    orthonormal contrast scores ``Y``."""
    n, p = Y.shape
    S = np.cov(Y, rowvar=False, ddof=1).reshape(p, p)
    tr = float(np.trace(S))
    if not tr > 0:
        return {"eps_gg": 1.0}
    S = S * (p / tr)  # scale-free: trace p, so det and W do not under- or overflow
    eps_gg = float(p / np.trace(S @ S))
    out = {"eps_gg": min(1.0, eps_gg)}
    den = p * (n - 1 - p * eps_gg)
    if n - 1 > p * eps_gg and den > 1e-9 * p * (n - 1):  # else undefined (few subjects)
        eps_hf = (n * p * eps_gg - 2) / den
        out["eps_hf"] = float(min(1.0, max(eps_gg, eps_hf)))
    if n - 1 < p or p < 2:  # singular covariance, or one contrast: no test of sphericity
        return out
    sign, logdet = np.linalg.slogdet(S)
    W = float(math.exp(logdet)) if sign > 0 else 0.0
    # Bartlett's χ² with Anderson's second-order term (accurate at small n):
    # P ≈ P(χ²_f ≥ z) + ω₂·[P(χ²_{f+4} ≥ z) − P(χ²_f ≥ z)]; the 3k (k = p + 1 conditions)
    # in ω₂ is as in R's mauchly.test, where Anderson writes 3p.
    k = p + 1
    nu = n - 1
    rho = 1 - (2 * p * p + p + 2) / (6 * p * nu)
    chi2 = -nu * rho * logdet if sign > 0 else float("inf")
    dfc = p * (p + 1) / 2 - 1
    w2 = ((p + 2) * (p - 1) * (p - 2) * (2 * p ** 3 + 6 * p * p + 3 * k + 2)
          / (288 * p * p * nu * nu * rho * rho))
    if math.isfinite(chi2):
        base = special.chdtrc(dfc, chi2)
        p_spher = float(min(1.0, max(0.0, base + w2 * (special.chdtrc(dfc + 4, chi2) - base))))
    else:
        p_spher = 0.0
    out.update(W_mauchly=W, p_spher=p_spher)
    return out


# --------------------------------------------------------------------- identification
def identification_scores(data: pd.DataFrame, subject: str, correct: str,
                          repetition: str | None = None, group: str | None = None,
                          chance: float = 1 / 6, answer: str | None = None,
                          truth: str | None = None) -> dict[str, pd.DataFrame]:
    """Percent correct overall, per repetition and per group, with binomial tests against chance.

    Parameters
    ----------
    correct : column of 0/1 (1: all surfaces named right)
    chance : float
        Probability of a correct answer by guessing: naming three surfaces at random is
        right in 1 of 3! = 6 orders.
    answer, truth : columns of comma-separated names (as answered, as presented), for the
        confusion matrix.

    Returns
    -------
    dict of DataFrames
        ``summary``: ``scope`` (all, repetition k, last repetition, group g), ``n``,
        ``correct``, ``incorrect``, ``percent``, ``chance_percent``, ``p_binom``
        (one-sided exact binomial test, P(X ≥ correct) by chance);
        ``confusion`` (when answer and truth are given): rows presented, columns answered,
        counts per surface.

    Notes
    -----
    p_binom = Σ_{k' ≥ k} C(n, k') · chance^k' · (1 − chance)^(n − k').

    Examples
    --------
    The published counts (Table 3 of the reality-based models: 35 of 42 answers right):

    >>> import pandas as pd
    >>> from analysis import identification_scores
    >>> d = pd.DataFrame({"participant": [f"S{i // 3}" for i in range(42)],
    ...                   "correct": [1] * 35 + [0] * 7})
    >>> identification_scores(d, "participant", "correct")["summary"][
    ...     ["scope", "n", "correct", "percent"]].round(1)
      scope   n  correct  percent
    0   all  42       35     83.3
    """
    cols = [subject, correct] + [c for c in (repetition, group, answer, truth) if c]
    _check_columns(data, cols)
    c = pd.to_numeric(data[correct], errors="coerce")
    if c.isna().any() or not c.isin([0, 1]).all():
        raise StatsError(f"column {correct!r} must hold 0 or 1 for every answer")
    rows = []

    def add(scope, mask):
        k = int(c[mask].sum())
        n = int(mask.sum())
        if n == 0:
            return
        rows.append({"scope": scope, "n": n, "correct": k, "incorrect": n - k,
                     "percent": 100.0 * k / n, "chance_percent": 100.0 * chance,
                     "p_binom": float(stats.binomtest(k, n, chance,
                                                      alternative="greater").pvalue)})

    all_rows = pd.Series(True, index=data.index)
    add("all", all_rows)
    if repetition:
        reps = pd.to_numeric(data[repetition], errors="coerce")
        for r in sorted(reps.dropna().unique()):
            add(f"repetition {int(r)}", reps == r)
        last = reps == reps.groupby(data[subject]).transform("max")
        add("last repetition", last)
    if group:
        for g in sorted(data[group].dropna().astype(str).unique()):
            if g:
                add(f"group {g}", data[group].astype(str) == g)
    out = {"summary": pd.DataFrame(rows)}
    if answer and truth:
        pairs = []
        for a, t in zip(data[answer].astype(str), data[truth].astype(str), strict=True):
            pairs += list(zip(t.split(","), a.split(","), strict=False))
        names = sorted({p for pair in pairs for p in pair if p})
        conf = pd.DataFrame(0, index=pd.Index(names, name="presented"),
                            columns=pd.Index(names, name="answered"))
        for t, a in pairs:
            if t and a:
                conf.loc[t, a] += 1
        out["confusion"] = conf
    return out


# --------------------------------------------------------------------- ordinal companions
def friedman(data: pd.DataFrame, dv: str, within: str, subject: str) -> pd.DataFrame:
    """Friedman test over the levels of ``within`` on per-subject means, with Kendall's W.

    The rank-based companion of the one-way :func:`rm_anova` for ordinal ratings. Subjects
    missing a level are left out (listwise). Ties within a subject get mid-ranks, and the
    statistic is corrected for them (as scipy and R's ``friedman.test``).

    Returns
    -------
    DataFrame, one row
        ``Source``, ``n``, ``k`` (levels), ``Q`` (χ² statistic), ``dof`` (k − 1),
        ``p_unc`` (χ² approximation), ``W`` (Kendall's coefficient of concordance,
        Q / (n (k − 1)), 0–1).

    Raises
    ------
    StatsError
        Fewer than 2 complete subjects or 3 levels, or every subject's ratings tied.

    Notes
    -----
    With R_j the rank sums, Q = [12 / (n k (k + 1)) Σ R_j² − 3 n (k + 1)] / C, where
    C = 1 − Σ (t³ − t) / (n (k³ − k)) over tie groups t; W = Q / (n (k − 1)).

    Examples
    --------
    >>> import analysis as A
    >>> df = A.datasets.read_dataset("ratings")
    >>> A.friedman(df, "rating", "sample", "participant")[["n", "k", "Q", "W"]].round(3)
       n  k       Q      W
    0  6  6  25.48  0.849
    """
    W_, subjects, levels = wide_means(data, dv, within, subject, centred=True)
    m = W_[~np.isnan(W_).any(axis=1)]
    n, k = m.shape
    if n < 2 or k < 3:
        raise StatsError(f"the Friedman test needs at least 2 complete subjects and 3 levels "
                         f"of {within!r}; has {n} and {k}")
    tol = _tol(m)
    m = np.array([tie_groups(row, tol) for row in m])  # values equal within tolerance tie
    ranks = np.apply_along_axis(stats.rankdata, 1, m)
    ties = 0.0
    for row in m:
        _, counts = np.unique(row, return_counts=True)
        ties += float(((counts ** 3) - counts).sum())
    c = 1 - ties / (n * (k ** 3 - k))
    if c <= 0:
        raise StatsError(f"every subject gave every level of {within!r} the same {dv}: the "
                         "Friedman test is undefined")
    rj = ranks.sum(axis=0)
    q = (12 / (n * k * (k + 1)) * float((rj ** 2).sum()) - 3 * n * (k + 1)) / c
    return pd.DataFrame([{"Source": within, "n": n, "k": k, "Q": q, "dof": k - 1,
                          "p_unc": float(special.chdtrc(k - 1, q)), "W": q / (n * (k - 1))}])


def _signrank_counts(n: int) -> np.ndarray:
    """Number of sign patterns of ranks 1..n giving each V = 0 … n(n+1)/2 (exact, float)."""
    c = np.zeros(n * (n + 1) // 2 + 1)
    c[0] = 1.0
    for k in range(1, n + 1):
        c[k:] = c[k:] + c[:-k].copy()
    return c


def _signrank_min_p(n: int) -> float:
    """The smallest two-sided p the signed-rank test can give with ``n`` differences: the
    exact 2/2ⁿ, or — when ties send it to the normal approximation — all ``n`` differences
    tied and of one sign, whichever is smaller (0 past the doubles' range)."""
    if n < 1:
        return 1.0
    exact = min(1.0, math.ldexp(1.0, 1 - n))
    if n < 2:
        return exact
    sigma = math.sqrt(n * (n + 1) * (2 * n + 1) / 24 - (n ** 3 - n) / 48)
    z = (n * (n + 1) / 4 - 0.5) / sigma
    return min(exact, 2.0 * float(special.ndtr(-z)))


def signed_rank_test(d: np.ndarray, tol: float = 0.0) -> dict:
    """Wilcoxon signed-rank test of paired differences ``d`` against 0, as R's
    ``wilcox.test(x, y, paired = TRUE, digits.rank = 7)`` (R's default ranks floating-point
    noise between equal fractions; here values within ``tol`` tie).

    Differences within ``tol`` of 0 are dropped (Wilcoxon's convention); absolute
    differences within ``tol`` of each other are tied (:func:`tie_groups`) and get mid-ranks.
    p is exact (the signed-rank distribution) when fewer than 50 differences remain and
    none were zero or tied; otherwise the normal approximation with the tie-corrected
    variance and a continuity correction of 1/2.

    Parameters
    ----------
    d : array of float
        Paired differences (A − B), in the ratings' units.
    tol : float
        Absolute tolerance for "equal" (same units as ``d``).

    Returns
    -------
    dict
        ``n`` (non-zero differences), ``V`` (sum of positive ranks), ``W`` (the smaller
        rank sum), ``p`` (two-sided), ``rbc`` ((R⁺ − R⁻) / (R⁺ + R⁻)), ``method``
        ("exact" or "normal"), ``zeros``, ``ties`` (whether any were dropped or tied).

    Examples
    --------
    >>> from analysis.stats import signed_rank_test
    >>> r = signed_rank_test(np.array([1.5, 2.0, -0.5, 3.0, 2.5]))
    >>> r["V"], round(r["p"], 4), r["method"]
    (14.0, 0.125, 'exact')

    R: ``wilcox.test(c(1.5, 2, -0.5, 3, 2.5))`` gives V = 14, p-value = 0.125.
    """
    d = np.asarray(d, float)
    if not np.isfinite(d).all():
        raise StatsError("a paired difference is missing or not finite: the signed-rank test "
                         "needs one difference per subject")
    zeros = bool((np.abs(d) <= tol).any())
    d = d[np.abs(d) > tol]
    n = int(d.size)
    if n == 0:
        raise StatsError("no non-zero difference: the signed-rank test is undefined")
    a = tie_groups(np.abs(d), tol)
    r = stats.rankdata(a)
    rp, rm = float(r[d > 0].sum()), float(r[d < 0].sum())
    _, t = np.unique(a, return_counts=True)
    ties = bool((t > 1).any())
    if n < 50 and not ties and not zeros:
        c = _signrank_counts(n)
        cdf = np.cumsum(c) / c.sum()
        v = int(round(rp))
        p = (1.0 - cdf[v - 1] if v > 0 else 1.0) if rp > n * (n + 1) / 4 else cdf[v]
        p, method = min(1.0, 2.0 * float(p)), "exact"
    else:
        z = rp - n * (n + 1) / 4
        sigma = math.sqrt(n * (n + 1) * (2 * n + 1) / 24 - float((t ** 3 - t).sum()) / 48)
        z = (z - math.copysign(0.5, z) if z else 0.0) / sigma
        p, method = min(1.0, 2.0 * float(special.ndtr(-abs(z)))), "normal"
    return {"n": n, "V": rp, "W": min(rp, rm), "p": p, "rbc": (rp - rm) / (rp + rm),
            "method": method, "zeros": zeros, "ties": ties}


def pairwise_wilcoxon(data: pd.DataFrame, dv: str, within: str, subject: str,
                      padjust: str = "holm") -> pd.DataFrame:
    """Wilcoxon signed-rank tests between every pair of levels, on per-subject means.

    Listwise, as :func:`pairwise_ttests`; each pair by :func:`signed_rank_test` (R's
    ``wilcox.test(paired = TRUE)`` rule: exact below 50 differences without zeros or ties,
    else normal with tie and continuity corrections). Differences and their absolute values
    within ``RTOL`` × the means' spread count as equal, so ties are seen exactly where the
    ratings are tied. A pair with no non-zero difference has no test and is listed in
    ``attrs["constant_pairs"]``.

    Returns
    -------
    DataFrame, one row per pair
        ``A``, ``B``, ``n`` (non-zero differences), ``W_val`` (the smaller rank sum),
        ``V`` (the sum of positive ranks, R's statistic), ``p_unc``, ``p_corr``,
        ``p_adjust``, ``rbc`` (matched-pairs rank-biserial correlation,
        (R⁺ − R⁻) / (R⁺ + R⁻), positive when A > B), ``method`` (exact or normal).

    Notes
    -----
    With n differences the smallest two-sided exact p is 2/2ⁿ; after Holm over m pairs the
    smallest adjusted p is m · 2/2ⁿ (55 pairs, n = 11: 0.054), so at small n no pair can
    reach α = .05 whatever the data: ``attrs["p_floor"]`` gives that bound.
    """
    W_, _subjects, levels = wide_means(data, dv, within, subject, centred=True)
    m = W_[~np.isnan(W_).any(axis=1)]
    tol = _tol(m)
    rows, constant = [], []
    for a, b in itertools.combinations(range(len(levels)), 2):
        d = m[:, a] - m[:, b]
        if not (np.abs(d) > tol).any():
            constant.append((levels[a], levels[b], "no difference for any subject"))
            continue
        r = signed_rank_test(d, tol)
        rows.append({"A": levels[a], "B": levels[b], "n": r["n"], "W_val": r["W"],
                     "V": r["V"], "p_unc": r["p"], "rbc": r["rbc"], "method": r["method"]})
    out = pd.DataFrame(rows, columns=["A", "B", "n", "W_val", "V", "p_unc", "rbc", "method"])
    out.insert(6, "p_corr", p_adjust(out["p_unc"].to_numpy(), padjust))
    out.insert(7, "p_adjust", padjust)
    out.attrs["constant_pairs"] = constant
    n_all = m.shape[0]
    n_pairs = len(rows)
    floor = _signrank_min_p(n_all)
    if padjust in ("holm", "bonf"):
        floor = min(1.0, floor * n_pairs)
    out.attrs["p_floor"] = floor
    return out


def dz_ci(dz: float, n: int, alpha: float = 0.05) -> tuple[float, float]:
    """Confidence interval of Cohen's d_z from the noncentral t distribution.

    t = d_z·√n follows a noncentral t with n − 1 degrees of freedom and noncentrality
    δ = d_z·√n; the interval inverts its CDF (Steiger & Fouladi 1997) and divides by √n.

    Examples
    --------
    >>> [round(x, 3) for x in dz_ci(0.8, 20)]
    [0.286, 1.298]
    """
    if n < 2 or not math.isfinite(dz):
        raise StatsError(f"a CI of d_z needs n >= 2 and a finite d_z; got n = {n}, d_z = {dz}")
    from scipy import optimize

    t, df = dz * math.sqrt(n), n - 1

    def cdf(nc: float) -> float:
        # P(T <= t | nc) falls from 1 to 0 as nc grows; far in its tails scipy may return
        # NaN, which is the limit on that side
        v = float(special.nctdtr(df, nc, t))
        return v if math.isfinite(v) else (1.0 if nc < t else 0.0)

    def solve(target):
        lo = hi = t
        step = 1.0
        while cdf(lo) <= target:
            lo, step = lo - step, step * 2
        step = 1.0
        while cdf(hi) >= target:
            hi, step = hi + step, step * 2
        return optimize.brentq(lambda nc: cdf(nc) - target, lo, hi, xtol=1e-12)

    return solve(1 - alpha / 2) / math.sqrt(n), solve(alpha / 2) / math.sqrt(n)


def np2_ci(F: float, df1: float, df2: float, alpha: float = 0.05) -> tuple[float, float]:
    """Confidence interval of partial η² by inverting the noncentral F distribution.

    The noncentrality λ with P(F' ≤ F | λ) = 1 − α/2 (lower) and α/2 (upper) — 0 when even
    λ = 0 leaves less — becomes η² = λ / (λ + df2), as R's ``effectsize::F_to_eta2(F, df1,
    df2, alternative = "two.sided")`` converts it (Steiger 2004 divides by the total
    N = df1 + df2 + 1 of a between-subjects design, which has no counterpart within
    subjects). The lower bound is above 0 exactly when p < α/2. (effectsize's own search
    stops early at F near 0: rubber's slope, F = 0.020, gets 0.243 where the root of R's
    ``pf`` is 0.249, which this function finds.)

    Examples
    --------
    >>> [round(x, 3) for x in np2_ci(10.0, 2, 20)]
    [0.145, 0.695]

    R: ``effectsize::F_to_eta2(10, 2, 20, alternative = "two.sided")`` gives
    [0.145339, 0.694645].
    """
    if not (math.isfinite(F) and F >= 0 and df1 > 0 and df2 > 0):
        raise StatsError(f"a CI of partial η² needs a finite F ≥ 0 and positive degrees of "
                         f"freedom; got F = {F}, df = ({df1}, {df2})")
    from scipy import optimize

    def cdf(lam: float) -> float:
        v = float(special.ncfdtr(df1, df2, lam, F))
        return v if math.isfinite(v) else 0.0

    def solve(target: float) -> float:
        if cdf(0.0) <= target:
            return 0.0
        hi = max(1.0, F * df1)
        while cdf(hi) > target:
            hi *= 2
        return optimize.brentq(lambda lam: cdf(lam) - target, 0.0, hi, xtol=1e-10)

    def eta(lam: float) -> float:
        return lam / (lam + df2)

    return eta(solve(1 - alpha / 2)), eta(solve(alpha / 2))


def participant_identification_test(data: pd.DataFrame, subject: str, correct: str,
                                    chance: float = 1 / 6, group: str | None = None
                                    ) -> pd.DataFrame:
    """Identification against chance with each person as the unit (repeated answers).

    Each participant's proportion of correct repetitions is one observation; a one-sided
    exact sign test asks whether more participants than chance would give are above the
    chance proportion, and a one-sample t-test compares the mean proportion with chance.
    Unlike the binomial test over all answers, neither treats one person's repeated answers
    as independent.

    With ``group`` (a between-subject factor, e.g. expert/novice) and exactly two groups,
    the groups' proportions are compared by a two-sided Mann–Whitney U test (exact for
    small groups without ties; scipy's ``method="auto"``): ``attrs["groups"]`` holds
    ``group_a``, ``group_b``, ``n_a``, ``n_b``, ``mean_percent_a``, ``mean_percent_b``,
    ``U``, ``p_mwu``.

    Returns
    -------
    DataFrame, one row
        ``n`` (participants), ``mean_percent``, ``chance_percent``, ``above`` (participants
        above chance), ``p_sign`` (one-sided exact sign test of ``above`` against 1/2 among
        participants not at chance), ``t``, ``dof``, ``p_t`` (one-sided).
    """
    _check_columns(data, [subject, correct])
    c = pd.to_numeric(data[correct], errors="coerce")
    if c.isna().any() or not c.isin([0, 1]).all():
        raise StatsError(f"column {correct!r} must hold 0 or 1 for every answer")
    p = c.groupby(data[subject], observed=True).mean()
    n = int(p.size)
    if n < 2:
        raise StatsError(f"a per-participant test needs at least 2 participants, has {n}")
    above, below = int((p > chance).sum()), int((p < chance).sum())
    p_sign = float(stats.binomtest(above, above + below, 0.5, alternative="greater").pvalue) \
        if above + below else 1.0
    sd = float(p.std(ddof=1))
    row = {"n": n, "mean_percent": 100 * float(p.mean()), "chance_percent": 100 * chance,
           "above": above, "p_sign": p_sign}
    if sd > _tol(p.to_numpy()) + 1e-15:
        t = (float(p.mean()) - chance) / (sd / math.sqrt(n))
        row.update(t=t, dof=n - 1, p_t=float(special.stdtr(n - 1, -t)))
    out = pd.DataFrame([row])
    if group is not None:
        _check_columns(data, [group])
        g = data.groupby(subject, observed=True)[group].first().astype(str)
        names = sorted(x for x in g.unique() if x)
        if len(names) == 2:
            a, b = (p[g.reindex(p.index) == x] for x in names)
            if len(a) and len(b):
                res = stats.mannwhitneyu(a, b, alternative="two-sided", method="auto")
                out.attrs["groups"] = {"group_a": names[0], "group_b": names[1],
                                       "n_a": int(len(a)), "n_b": int(len(b)),
                                       "mean_percent_a": 100 * float(a.mean()),
                                       "mean_percent_b": 100 * float(b.mean()),
                                       "U": float(res.statistic), "p_mwu": float(res.pvalue)}
    return out


# --------------------------------------------------------------------- model companions
def _reml_intercept(y: np.ndarray, X: np.ndarray, g: np.ndarray) -> dict:
    """REML fit of ``y = X β + u_g + e`` (one random intercept per group ``g``).

    The likelihood is profiled onto the variance ratio γ = σ²_u / σ²_e, which a bounded
    scalar search finds to 1e-12 (a coarse grid first, so the search starts in the right
    valley); each evaluation costs O(N p²) through the Sherman–Morrison inverse of each
    group's covariance, so the fit scales with the number of rows, not participants².

    Returns
    -------
    dict with ``beta``, ``cov`` (of β), ``var_u``, ``var_e``, ``gamma``, ``reml`` (−2 ×
    restricted log-likelihood, up to a constant).
    """
    from scipy import optimize

    n, p = X.shape
    if n <= p:
        raise StatsError(f"the mixed model has {n} ratings for {p} fixed effects: no "
                         "residual variance can be estimated")
    gi = np.unique(g, return_inverse=True)[1]
    counts = np.bincount(gi).astype(float)
    Xs = np.zeros((counts.size, p))
    np.add.at(Xs, gi, X)  # per-group column sums (1'X_i)
    ys = np.bincount(gi, weights=y)
    XtX, Xty, yty = X.T @ X, X.T @ y, float(y @ y)

    def parts(gamma: float):
        c = gamma / (1.0 + gamma * counts)  # V_i⁻¹ = I − c_i 11' (in units of σ²_e)
        A = XtX - (Xs * c[:, None]).T @ Xs
        b = Xty - (Xs * c[:, None]).T @ ys
        beta = np.linalg.solve(A, b)
        rss = yty - float(c @ ys ** 2) - float(beta @ b)
        return A, beta, max(rss, 0.0)

    def crit(theta: float) -> float:  # −2 REML log-likelihood profiled over σ²_e and β
        gamma = theta * theta
        A, _beta, rss = parts(gamma)
        sign, logdet = np.linalg.slogdet(A)
        if sign <= 0 or rss <= 0:
            return np.inf
        return ((n - p) * math.log(rss / (n - p)) + float(np.log1p(gamma * counts).sum())
                + logdet)

    grid = np.concatenate([[0.0], np.geomspace(1e-4, 1e3, 57)])
    vals = np.array([crit(t) for t in grid])
    k = int(np.argmin(vals))
    if k == grid.size - 1:  # σ²_u/σ²_e ≥ 1e6: the trials within a subject do not vary
        raise StatsError("the mixed model is undefined: within each participant the ratings "
                         "are explained by the fixed effects (no residual variance)")
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    if not np.isfinite(vals).any():
        raise StatsError("the mixed model is undefined: every rating is explained by the "
                         "fixed effects (no residual variance)")
    res = optimize.minimize_scalar(crit, bounds=(lo, hi), method="bounded",
                                   options={"xatol": 1e-12 * max(hi, 1.0)})
    theta = float(res.x) if res.fun <= vals[k] else float(grid[k])
    if vals[0] <= crit(theta) + 1e-12 * abs(vals[0]):
        theta = 0.0  # the boundary: no participant variance (lme4: a singular fit, SD 0)
    gamma = theta * theta
    A, beta, rss = parts(gamma)
    if rss <= RTOL ** 2 * n:  # the data's scale is 1 here: rounding, not residual variance
        raise StatsError("the mixed model is undefined: every rating is explained by the "
                         "fixed effects (no residual variance)")
    var_e = rss / (n - p)
    return {"beta": beta, "cov": var_e * np.linalg.inv(A), "var_u": gamma * var_e,
            "var_e": var_e, "gamma": gamma, "reml": crit(theta),
            "converged": bool(res.success) or theta == float(grid[k]) or theta == 0.0}


def mixed_oneway(data: pd.DataFrame, dv: str, within: str, subject: str,
                 between: str | None = None) -> pd.DataFrame:
    """Linear mixed model on trial-level ratings: ``dv ~ C(within)`` with a random
    intercept per subject (REML), and the Wald test that every level has the same mean.

    Unlike the repeated-measures ANOVA it keeps subjects with missing cells (each trial
    counts where it was recorded). With ``between`` (a between-subject factor such as
    expert/novice) the model is ``dv ~ C(within) * C(between)`` and there is a row for
    ``within``, ``between`` and their interaction. Factors are coded with sum-to-zero
    contrasts, so each row is a type-III Wald test (R: ``car::Anova(lmer(...), type = 3)``
    under ``contr.sum``): a main effect averaged over the other factor's levels.

    Returns
    -------
    DataFrame, one row per tested term
        ``Source``, ``n_subjects``, ``n_obs``, ``chi2`` (Wald), ``dof``, ``p_unc``,
        ``sd_subject`` (random-intercept SD), ``sd_resid``, ``converged``.
        ``attrs["fixed"]``: every fixed-effect coefficient with its SE and 95 % Wald CI
        (sum-coded: level k's coefficient is its mean minus the mean of the level means).

    Raises
    ------
    StatsError
        Fewer than 2 subjects or levels, no variation, or a design that cannot be fitted.

    Notes
    -----
    The restricted likelihood is profiled onto the variance ratio and maximised by a
    bounded scalar search (:func:`_reml_intercept`); lme4's ``lmer`` finds the same
    optimum (the variance components agree to ~1e-7 on the R reference studies).
    """
    import patsy

    cols = [dv, within, subject] + ([between] if between else [])
    _check_columns(data, cols)
    _check_values(data, dv, cols[1:])
    d = data[cols].copy()
    d[dv] = pd.to_numeric(d[dv], errors="coerce")
    d = d.dropna()
    levels = list(dict.fromkeys(d[within]))
    if d[subject].nunique() < 2 or len(levels) < 2:
        raise StatsError(f"a mixed model needs at least 2 subjects and 2 levels of {within!r}")
    if between and d.groupby(between)[subject].nunique().lt(2).any() | (d[between].nunique() < 2):
        raise StatsError(f"a between-subject factor needs at least 2 groups of {between!r} "
                         "with 2 subjects each")
    v = d[dv].to_numpy(float)
    anchor = _anchor(v)
    v = v - anchor  # exact for ratings: a shift of every rating changes nothing
    scale = float(v.max() - v.min())
    if scale <= 0:
        raise StatsError(f"every {dv} is the same: the mixed model is undefined")
    d = d.assign(_y=v / scale,
                 _x=pd.Categorical(d[within].astype(str), [str(x) for x in levels]))
    formula = "C(_x, Sum)"
    if between:
        d = d.assign(_b=d[between].astype(str))
        formula = "C(_x, Sum) * C(_b, Sum)"
    X = patsy.dmatrix(formula, d, return_type="dataframe")
    if np.linalg.matrix_rank(X.to_numpy()) < X.shape[1]:
        raise StatsError(f"the mixed model's effects are not estimable: some combination of "
                         f"{within}{' and ' + between if between else ''} has no rating")
    fit = _reml_intercept(d["_y"].to_numpy(), X.to_numpy(), d[subject].astype(str).to_numpy())
    names = list(X.columns)
    terms = {within: lambda n: n.startswith("C(_x") and ":" not in n}
    if between:
        terms[between] = lambda n: n.startswith("C(_b")
        terms[f"{within} * {between}"] = lambda n: n.startswith("C(_x") and ":C(_b" in n
    rows = []
    for source, pick in terms.items():
        idx = [i for i, n in enumerate(names) if pick(n)]
        b = fit["beta"][idx]
        chi2 = float(b @ np.linalg.solve(fit["cov"][np.ix_(idx, idx)], b))
        rows.append({"Source": source, "n_subjects": int(d[subject].nunique()),
                     "n_obs": int(len(d)), "chi2": chi2, "dof": len(idx),
                     "p_unc": float(special.chdtrc(len(idx), chi2)),
                     "sd_subject": math.sqrt(fit["var_u"]) * scale,
                     "sd_resid": math.sqrt(fit["var_e"]) * scale,
                     "converged": fit["converged"]})
    out = pd.DataFrame(rows)
    se = np.sqrt(np.diag(fit["cov"]))
    z = float(special.ndtri(0.975))
    label = {"_x": within, "_b": between or ""}
    fixed = []
    for n, bk, sk in zip(names, fit["beta"], se, strict=True):
        shift = anchor if n == "Intercept" else 0.0
        fixed.append({"term": re.sub(r"C\((_\w), Sum\)\[S\.",
                                     lambda m: f"{label[m.group(1)]}[", n),
                      "estimate": float(bk) * scale + shift, "se": float(sk) * scale,
                      "ci_low": (float(bk) - z * float(sk)) * scale + shift,
                      "ci_high": (float(bk) + z * float(sk)) * scale + shift})
    out.attrs["fixed"] = fixed
    return out
