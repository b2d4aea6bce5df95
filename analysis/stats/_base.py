"""What every statistic shares: its error, the tolerance within which values count as equal,
and the checks of columns and values."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

__all__ = ["StatsError", "tie_groups", "PADJUST", "RTOL", "MISSING"]


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
