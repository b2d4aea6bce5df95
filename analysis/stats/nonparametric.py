"""Rank tests of repeated measures: the Friedman test and Wilcoxon signed-rank tests (exact
where R's wilcox.test is exact)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd
from scipy import special, stats

from ._base import StatsError, _tol, tie_groups
from .multicomp import p_adjust
from .shaping import wide_means

__all__ = ["friedman", "pairwise_wilcoxon", "signed_rank_test"]


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
