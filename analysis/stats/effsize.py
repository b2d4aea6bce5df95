"""Confidence intervals of effect sizes: d_z from the noncentral t, partial eta squared from
the noncentral F."""

from __future__ import annotations

import math

from scipy import special

from ._base import StatsError

__all__ = ["dz_ci", "np2_ci"]


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
