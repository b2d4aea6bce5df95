"""From trial rows to what the tests take: per-subject cell means (long and wide), the
preflight that refuses data a test cannot analyse honestly, z-scores per subject."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import pandas as pd

from ._base import _anchor, _as_list, _check_columns, _check_values, _tol

__all__ = ["preflight", "zscore_by_subject", "cell_means", "wide_means"]


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
#: up to this many subjects a check's detail names each with what it misses
_NAMED = 20


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
    # each subject's distinct cells, counted at once (not a groupby per subject: 21,700
    # participants took minutes that way)
    subjects = clean.groupby(subject, observed=True).size().index
    per_subject = (clean.dropna(subset=w).drop_duplicates([subject, *w])
                   .groupby(subject, observed=True).size()
                   .reindex(subjects, fill_value=0))
    incomplete = per_subject[per_subject < n_cells]
    if len(incomplete):
        missing = n_cells - incomplete
        add("missing_cells", "; ".join(f"{s}: {k} of {n_cells} cells missing"
                                       for s, k in missing.items())
            if len(missing) <= _NAMED else
            f"{len(missing)} subjects miss {missing.min()}–{missing.max()} of {n_cells} cells "
            "(each named in subjects_excluded)",
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
