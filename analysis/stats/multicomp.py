"""Corrections for multiple comparisons (Holm, Bonferroni, Benjamini–Hochberg), as R's p.adjust."""

from __future__ import annotations

import numpy as np

from ._base import PADJUST, StatsError

__all__ = ["p_adjust"]


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
