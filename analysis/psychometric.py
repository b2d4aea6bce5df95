"""Psychometric functions fitted to forced-choice answers by maximum likelihood.

The function of intensity x (the procedure's units) is

    ψ(x) = γ + (1 − γ − λ)·F(x; m, w)

with the guess rate γ fixed (1/n for n alternatives), the lapse rate λ free in
[0, ``lapse_max``], and F a cumulative normal, a logistic or a Weibull. F is parametrised as
psignifit 4 does (Schütt et al. 2016), so the two can be compared number for number: m is
where F = 1/2, w the width from F = 0.05 to F = 0.95. The Weibull is F(x) = 1 − exp(−(x/α)^β)
for x > 0, which is a Gumbel (minimum) distribution of ln x: its m and w are in ln x, as
psignifit's ``weibull`` on log-transformed levels.

A *threshold* is read at a stated criterion: the intensity where ψ (the proportion correct
as observed, lapses and guesses included) reaches it; a 2-down/1-up staircase converges on
70.7 %, a 3-down/1-up on 79.4 %. Thresholds at different criteria differ (a viscosity Weber
fraction of 19 % at 71 % correct was 34 % at 84 % in the review Jones & Tan 2013 cite), so
every threshold here carries its criterion.

Its confidence interval is the profile likelihood interval (the thresholds t for which the
likelihood maximised with the threshold held at t is within χ²₁(1 − α)/2 of the maximum),
not a bootstrap: it needs no random numbers and is exact in its own terms; an end beyond
the intensities tested is not extrapolated but said (None, with ``ci_note``). Goodness of
fit is the deviance against the saturated model, its p from a parametric bootstrap (the
deviance of ``gof_samples`` data sets drawn from the fitted function at the same
intensities and counts, each refitted; Wichmann & Hill 2001), with a generator from the
recorded ``seed``: adaptive data have few trials per intensity, where the χ² approximation
of the deviance does not hold.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import optimize, special, stats

__all__ = ["FUNCTIONS", "Psychometric", "fit_psychometric", "psychometric_fit",
           "fit_tracks", "levels", "deviance", "psi"]

FUNCTIONS = ("weibull", "normal", "logistic")
_ALPHA_W = 0.05  # the width spans F = 0.05 to 0.95, as psignifit's default
_LOG_TINY = 1e-12


def _cdf(function: str, z):
    """The standard cdf of F's family at z (scipy.special: the distributions' own methods
    cost more than the likelihood)."""
    if function == "normal":
        return special.ndtr(z)
    if function == "logistic":
        return special.expit(z)
    return -np.expm1(-np.exp(np.minimum(z, 50.0)))  # Gumbel (minimum): the Weibull of ln x


def _pdf(function: str, z):
    if function == "normal":
        return np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)
    if function == "logistic":
        e = special.expit(z)
        return e * (1 - e)
    z = np.minimum(z, 50.0)
    return np.exp(z - np.exp(z))


def _ppf(function: str, q: float) -> float:
    if function == "normal":
        return float(special.ndtri(q))
    if function == "logistic":
        return float(special.logit(q))
    return float(np.log(-np.log1p(-q)))


def _check_function(function: str) -> None:
    if function not in FUNCTIONS:
        raise ValueError(f"function must be one of {', '.join(FUNCTIONS)}, got {function!r}")


def _axis(function: str, x):
    """The axis F is a location-scale family on: x, or ln x for the Weibull."""
    x = np.asarray(x, dtype=float)
    if function != "weibull":
        return x
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(np.where(x > 0, x, np.nan))


def _back(function: str, u):
    return np.exp(u) if function == "weibull" else u


def _scale(function: str, w):
    return w / (_ppf(function, 1 - _ALPHA_W) - _ppf(function, _ALPHA_W))


def _loc(function: str, m, w):
    return m - _scale(function, w) * _ppf(function, 0.5)


def psi(function: str, x, m, w, guess: float, lapse):
    """ψ(x) (module docstring); x ≤ 0 gives the guess rate for the Weibull. ``m``, ``w`` and
    ``lapse`` broadcast against ``x``."""
    u = _axis(function, x)
    f = _cdf(function, (u - _loc(function, m, w)) / _scale(function, w))
    f = np.where(np.isnan(u), 0.0, f)
    return guess + (1.0 - guess - lapse) * f


def deviance(k, n, p) -> float:
    """2 Σ [k ln(k / np) + (n − k) ln((n − k) / n(1 − p))], 0·ln 0 = 0."""
    k, n, p = (np.asarray(a, dtype=float) for a in (k, n, p))
    p = np.clip(p, _LOG_TINY, 1 - _LOG_TINY)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(k > 0, k * np.log(k / (n * p)), 0.0)
        b = np.where(n - k > 0, (n - k) * np.log((n - k) / (n * (1 - p))), 0.0)
    return float(2.0 * np.sum(a + b))


def _loglik(k, n, p) -> float:
    p = np.clip(p, _LOG_TINY, 1 - _LOG_TINY)
    return float(np.sum(k * np.log(p) + (n - k) * np.log1p(-p)))


def levels(x, correct) -> pd.DataFrame:
    """Trials pooled by intensity: ``x``, ``k`` (right), ``n`` (trials), ascending."""
    d = pd.DataFrame({"x": np.asarray(x, dtype=float),
                      "k": np.asarray(correct, dtype=float)})
    d = d.dropna()
    g = d.groupby("x")["k"].agg(["sum", "count"]).reset_index()
    return pd.DataFrame({"x": g["x"].to_numpy(), "k": g["sum"].to_numpy(),
                         "n": g["count"].to_numpy()})


@dataclass(frozen=True)
class Psychometric:
    """A fitted function (:func:`fit_psychometric`); ``m`` and ``w`` on F's axis (ln x for
    the Weibull), ``lapse`` λ, ``guess`` γ."""

    function: str
    m: float
    w: float
    lapse: float
    guess: float
    loglik: float

    def __call__(self, x):
        return psi(self.function, x, self.m, self.w, self.guess, self.lapse)

    def threshold(self, criterion: float) -> float:
        """The intensity where ψ = ``criterion`` (NaN where ψ never reaches it)."""
        f = (criterion - self.guess) / (1.0 - self.guess - self.lapse)
        if not 0.0 < f < 1.0:
            return math.nan
        u = _loc(self.function, self.m, self.w) + _scale(self.function, self.w) * \
            _ppf(self.function, f)
        return float(_back(self.function, u))

    def slope(self, x: float) -> float:
        """dψ/dx at ``x`` [1/units]."""
        s = _scale(self.function, self.w)
        u = float(_axis(self.function, x))
        dens = _pdf(self.function, (u - _loc(self.function, self.m, self.w)) / s) / s
        du = 1.0 / x if self.function == "weibull" else 1.0
        return float((1.0 - self.guess - self.lapse) * dens * du)

    @property
    def weibull(self) -> tuple[float, float] | None:
        """(α, β) of the Weibull, F(x) = 1 − exp(−(x/α)^β) (None for the other functions)."""
        if self.function != "weibull":
            return None
        return float(np.exp(_loc("weibull", self.m, self.w))), \
            float(1.0 / _scale("weibull", self.w))


def _nll(function, x, k, n, m, w, guess, lam):
    """−log L, broadcasting over arrays of m, w, λ (their shapes, then the levels last)."""
    p = psi(function, x, np.asarray(m)[..., None], np.asarray(w)[..., None], guess,
            np.asarray(lam)[..., None])
    p = np.clip(p, _LOG_TINY, 1 - _LOG_TINY)
    return -np.sum(k * np.log(p) + (n - k) * np.log1p(-p), axis=-1)


def fit_psychometric(x, k, n, function: str = "weibull", guess: float = 0.5,
                     lapse_max: float = 0.06, fixed: dict | None = None,
                     start: Psychometric | None = None) -> Psychometric:
    """The maximum-likelihood function for ``k`` right of ``n`` trials at intensities ``x``.

    Parameters
    ----------
    x, k, n : array-like
        Intensities [units], right answers and trials at each.
    function : {'weibull', 'normal', 'logistic'}
    guess : float
        γ, fixed (1/2 for two alternatives).
    lapse_max : float
        λ is free in [0, lapse_max].
    fixed : dict, optional
        ``{"threshold": (criterion, t)}`` holds the threshold at ``criterion`` at ``t`` (the
        profile likelihood of the threshold).
    start : Psychometric, optional
        Where the search starts (a nearby fit); by default from a grid over the data.

    Raises
    ------
    ValueError
        For data it cannot fit: fewer than two intensities, a Weibull at x ≤ 0, counts that
        are not counts.
    """
    _check_function(function)
    x, k, n = (np.asarray(a, dtype=float) for a in (x, k, n))
    if x.shape != k.shape or x.shape != n.shape or x.size < 2:
        raise ValueError(f"needs trials at two intensities at least, got {x.size}")
    if np.any(n < 1) or np.any(k < 0) or np.any(k > n) or not np.all(np.isfinite(x)):
        raise ValueError("k must lie in 0..n with n ≥ 1 at finite intensities")
    if function == "weibull" and np.any(x <= 0):
        raise ValueError("a Weibull is fitted to intensities above 0 only")
    if not 0 < guess < 1 or not 0 <= lapse_max < 1 - guess:
        raise ValueError(f"guess {guess:g} and lapse_max {lapse_max:g} leave no range")
    u = _axis(function, x)
    lo, hi = float(np.min(u)), float(np.max(u))
    span = max(hi - lo, 1e-3 * max(abs(lo), abs(hi), 1.0))
    hold = (fixed or {}).get("threshold")
    q05 = _ppf(function, 0.5)

    def m_held(w, lam):
        crit, t = hold
        f = np.clip((crit - guess) / (1.0 - guess - lam), 1e-9, 1 - 1e-9)
        s = _scale(function, w)
        ppf = _ppf(function, float(f)) if np.ndim(f) == 0 else np.vectorize(
            lambda q: _ppf(function, q))(f)
        return float(_axis(function, t)) - s * ppf + s * q05

    if start is not None:
        guess0 = np.array([[start.m, math.log(start.w), start.lapse]])
    else:  # a grid over the data's range, every point at once
        ms = np.linspace(lo - 0.25 * span, hi + 0.25 * span, 25)
        ws = span * np.geomspace(0.02, 8.0, 25)
        lams = np.linspace(0.0, lapse_max, 4) if lapse_max > 0 else np.array([0.0])
        if hold is None:
            M, W, L = np.meshgrid(ms, ws, lams, indexing="ij")
        else:  # m follows from the held threshold: a finer grid of w and λ alone
            W, L = np.meshgrid(span * np.geomspace(0.02, 8.0, 60),
                               np.linspace(0.0, lapse_max, 7) if lapse_max > 0
                               else np.array([0.0]), indexing="ij")
            M = m_held(W, L)
        v = _nll(function, x, k, n, M, W, guess, L)
        i = np.unravel_index(int(np.argmin(v)), v.shape)
        guess0 = np.array([[M[i], math.log(W[i]), L[i]]])
    m0, lw0, lam0 = guess0[0]
    lw_b = (math.log(span * 1e-4), math.log(span * 1e3))
    lam0 = min(max(lam0, 0.0), lapse_max)
    jac = None
    if hold is None:
        c = _ppf(function, 1 - _ALPHA_W) - _ppf(function, _ALPHA_W)
        ok = ~np.isnan(u)

        def f_(th):
            return float(_nll(function, x, k, n, th[0], math.exp(th[1]), guess, th[2]))

        def jac(th):  # the gradient by hand: L-BFGS-B then needs a few evaluations only
            m, s, lam = th[0], math.exp(th[1]) / c, th[2]
            z = np.where(ok, (u - m) / s + q05, -np.inf)
            big_f, dens = _cdf(function, z), np.where(ok, _pdf(function, z), 0.0)
            p = np.clip(guess + (1 - guess - lam) * big_f, _LOG_TINY, 1 - _LOG_TINY)
            g = -(k / p - (n - k) / (1 - p))
            a = 1 - guess - lam
            zz = np.where(ok, z - q05, 0.0)
            return np.array([np.sum(g * (-a * dens / s)), np.sum(g * (-a * dens * zz)),
                             np.sum(g * -big_f)])
        x0 = [m0, min(max(lw0, lw_b[0]), lw_b[1]), lam0]
        bounds = [(lo - 10 * span, hi + 10 * span), lw_b, (0.0, lapse_max)]
    else:
        def f_(th):
            w = math.exp(th[0])
            return float(_nll(function, x, k, n, m_held(w, th[1]), w, guess, th[1]))
        x0 = [min(max(lw0, lw_b[0]), lw_b[1]), lam0]
        bounds = [lw_b, (0.0, lapse_max)]
    res = optimize.minimize(f_, np.asarray(x0), method="L-BFGS-B", bounds=bounds, jac=jac)
    th = res.x if res.fun <= f_(np.asarray(x0)) else np.asarray(x0)
    if hold is None:
        m, w, lam = th[0], math.exp(th[1]), th[2]
    else:
        w, lam = math.exp(th[0]), th[1]
        m = m_held(w, lam)
    return Psychometric(function, float(m), float(w), float(lam), guess, -float(f_(th)))


def _profile_ci(fit: Psychometric, x, k, n, criterion: float, lapse_max: float,
                alpha: float) -> tuple[float | None, float | None, str]:
    """The profile-likelihood interval of the threshold at ``criterion``."""
    t0 = fit.threshold(criterion)
    if not math.isfinite(t0):
        return None, None, "no threshold: the fitted function does not reach the criterion"
    cut = stats.chi2.ppf(1 - alpha, 1) / 2.0

    def drop(t):
        held = fit_psychometric(x, k, n, fit.function, fit.guess, lapse_max,
                                fixed={"threshold": (criterion, t)})
        return fit.loglik - held.loglik - cut

    lo_x, hi_x = float(np.min(x)), float(np.max(x))
    span = hi_x - lo_x
    # beyond the intensities tested the likelihood still constrains the threshold (through
    # the function's form): the search goes on to a tenth of the lowest (a span below, for
    # a function on x itself) and ten times the highest, and says when it had to
    log = fit.function == "weibull"
    far = {"lower": lo_x / 10 if log else lo_x - span,
           "upper": hi_x * 10 if log else hi_x + span}
    reach = {"lower": "a tenth of the lowest intensity tested" if log else
             "a span of the intensities tested below the lowest",
             "upper": "ten times the highest intensity tested" if log else
             "a span of the intensities tested above the highest"}
    out, notes = [], []
    for edge, side in ((lo_x, "lower"), (hi_x, "upper")):
        inside = (side == "lower" and edge < t0) or (side == "upper" and edge > t0)
        if inside and drop(edge) >= 0:  # the interval closes within the intensities tested
            out.append(float(optimize.brentq(drop, *sorted((edge, t0)),
                                             xtol=1e-6 * abs(t0) + 1e-12)))
            continue
        outer = far[side]
        if drop(outer) < 0:
            out.append(None)
            notes.append(f"the {side} end lies beyond {reach[side]}")
            continue
        inner = edge if inside else t0
        out.append(float(optimize.brentq(drop, *sorted((outer, inner)),
                                         xtol=1e-6 * abs(t0) + 1e-12)))
        notes.append(f"the {side} end is extrapolated beyond the intensities tested")
    return out[0], out[1], "; ".join(notes)


def psychometric_fit(x, correct, *, function: str = "weibull", criterion: float = 0.75,
                     guess: float = 0.5, lapse_max: float = 0.06, alpha: float = 0.05,
                     gof_samples: int = 199, seed: int = 0) -> dict:
    """Fit a psychometric function to forced-choice trials and read its threshold.

    Parameters
    ----------
    x : array-like
        Each trial's intensity [the procedure's units].
    correct : array-like of 0/1
        Whether each answer was right.
    function : {'weibull', 'normal', 'logistic'}
    criterion : float
        The proportion correct the threshold is read at (of ψ, as observed).
    guess : float
        γ: 1/n for n alternatives.
    lapse_max : float
        λ's upper bound.
    alpha : float
        1 − the confidence level of the threshold's interval.
    gof_samples : int
        Bootstrap data sets for the deviance's p (0: none).
    seed : int
        The bootstrap generator's seed (recorded in the result).

    Returns
    -------
    dict
        ``function``, ``criterion``, ``threshold`` [units] with ``ci_low`` and ``ci_high``
        (``ci_note`` says where an end was extrapolated beyond the intensities tested, or
        lies too far beyond them to say: None), ``ci_level``, ``m`` and ``width``
        (psignifit's threshold and width of F, on ln x for the Weibull), ``alpha_w`` and
        ``beta`` (the Weibull's α, β; None otherwise), ``slope`` (dψ/dx at the threshold
        [1/units]), ``lapse``, ``lapse_max``, ``guess``, ``deviance``, ``gof_p``
        (bootstrap; None without samples), ``gof_samples``, ``seed``, ``n_trials``,
        ``n_levels``, ``loglik``.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.repeat([0.02, 0.05, 0.1, 0.2, 0.4], 20)
    >>> k = np.concatenate([np.r_[np.ones(n), np.zeros(20 - n)] for n in (10, 12, 15, 19, 20)])
    >>> r = psychometric_fit(x, k, gof_samples=0)
    >>> round(r["threshold"], 3), r["criterion"], r["n_trials"]
    (0.1, 0.75, 100)
    """
    lv = levels(x, correct)
    fit = fit_psychometric(lv["x"], lv["k"], lv["n"], function, guess, lapse_max)
    lo, hi, note = _profile_ci(fit, lv["x"].to_numpy(), lv["k"].to_numpy(),
                               lv["n"].to_numpy(), criterion, lapse_max, alpha)
    t = fit.threshold(criterion)
    dev = deviance(lv["k"], lv["n"], fit(lv["x"]))
    gof = None
    if gof_samples:
        rng = np.random.default_rng(seed)
        p = fit(lv["x"].to_numpy())
        devs = []
        for _ in range(gof_samples):
            kb = rng.binomial(lv["n"].to_numpy().astype(int), p)
            fb = fit_psychometric(lv["x"], kb, lv["n"], function, guess, lapse_max,
                                  start=fit)
            devs.append(deviance(kb, lv["n"], fb(lv["x"])))
        gof = float((1 + np.sum(np.asarray(devs) >= dev - 1e-9)) / (1 + gof_samples))
    wb = fit.weibull
    return {"function": function, "criterion": criterion,
            "threshold": t if math.isfinite(t) else None, "ci_low": lo, "ci_high": hi,
            "ci_level": 1 - alpha, "ci_note": note,
            "m": fit.m, "width": fit.w, "alpha_w": None if wb is None else wb[0],
            "beta": None if wb is None else wb[1],
            "slope": fit.slope(t) if math.isfinite(t) else None, "lapse": fit.lapse,
            "lapse_max": lapse_max, "guess": guess, "deviance": dev, "gof_p": gof,
            "gof_samples": gof_samples, "seed": seed, "n_trials": int(lv["n"].sum()),
            "n_levels": len(lv), "loglik": fit.loglik}


def fit_tracks(data: pd.DataFrame, by: Sequence[str], **kw) -> pd.DataFrame:
    """:func:`psychometric_fit` per group of ``data`` (columns ``intensity`` and
    ``correct``), one row each with the group's keys."""
    rows = []
    for key, g in data.groupby(list(by), sort=True):
        key = key if isinstance(key, tuple) else (key,)
        rows.append({**dict(zip(by, key, strict=True)),
                     **psychometric_fit(g["intensity"], g["correct"], **kw)})
    return pd.DataFrame(rows)
