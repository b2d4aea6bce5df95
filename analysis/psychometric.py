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

The threshold stated, and its interval, come from the posterior over (m, w, λ) on a grid
(:func:`threshold_posterior`): the threshold at the criterion is a function of the three,
its posterior median is the estimate and the central 1 − α of its marginal posterior the
credible interval. The priors are psignifit 4's defaults (m flat over the intensities tested
with cosine flanks of half their span; λ Beta(1, 10) within its bound; w within psignifit's
support, from the finest step between intensities to three times their span, with its cosine
flanks), except that w's is flat in ln w where psignifit's is flat in w: with adaptive data,
crowded around one point, a prior flat in w favours shallow functions and pulls the
threshold at a criterion below the point the procedure converged on (psignifit's stays
available as ``width_prior="psignifit"`` to show it). The posterior needs no random
numbers, and an adaptive procedure's choice of intensities, which depends on the answers
alone, leaves it unchanged (the likelihood principle); whether its interval holds the truth
at the nominal rate on adaptive data is measured by ``hapticlab bench thresholds`` for one
configuration (Weibull observers fitted with a Weibull, criterion 0.75, λ ≤ 0.06). An end
the answers do not bound — they fit as well (within χ²₁(1 − α)/2 in log likelihood) with the
threshold at the criterion held half the span of the intensities tested beyond them, where
m's prior ends — is not stated as a number but said (None, with ``ci_note``), and so is an
end the function may never reach. The maximum-likelihood threshold's profile likelihood
interval (the thresholds t for which the likelihood maximised with the threshold held at t
is within χ²₁(1 − α)/2 of the maximum) is kept for comparison (``interval="profile"``): on
adaptive data it is too narrow. Goodness of fit is the deviance against the saturated
model, its p from a parametric bootstrap (the deviance of ``gof_samples`` data sets drawn
from the fitted function at the same intensities and counts, each refitted; Wichmann &
Hill 2001), with a generator from the recorded ``seed``: adaptive data have few trials per
intensity, where the χ² approximation of the deviance does not hold.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import optimize, special, stats

__all__ = ["FUNCTIONS", "Psychometric", "fit_psychometric", "psychometric_fit",
           "threshold_posterior", "fit_tracks", "levels", "deviance", "psi", "LAPSE_PRIOR",
           "WIDTH_PRIORS"]

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


def _ppf_array(function: str, q):
    """:func:`_ppf` over an array."""
    q = np.asarray(q, dtype=float)
    if function == "normal":
        return special.ndtri(q)
    if function == "logistic":
        return special.logit(q)
    return np.log(-np.log1p(-q))


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


def _round_sig(x, digits: int = 12):
    """``x`` rounded to ``digits`` significant digits (0 and non-finite values as they are)."""
    x = np.asarray(x, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.where(np.isfinite(x) & (x != 0), np.floor(np.log10(np.abs(x))), 0.0)
    return np.round(x / 10.0 ** e, digits - 1) * 10.0 ** e


def levels(x, correct) -> pd.DataFrame:
    """Trials pooled by intensity: ``x``, ``k`` (right), ``n`` (trials), ascending.

    Intensities equal to 12 significant digits are one level: a procedure that steps in
    log units and back reaches the same intensity by sums that differ in the last bits."""
    x = np.asarray(x, dtype=float)
    d = pd.DataFrame({"x": x, "key": _round_sig(x), "k": np.asarray(correct, dtype=float)})
    d = d.dropna()
    g = d.groupby("key").agg(x=("x", "first"), sum=("k", "sum"), count=("k", "count"))
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


def _check_counts(function: str, x, k, n, guess: float, lapse_max: float):
    """``x``, ``k``, ``n`` as float arrays once they are data a function can be fitted to
    (:func:`fit_psychometric` and :func:`threshold_posterior` share this check).

    Raises
    ------
    ValueError
        An unknown function; fewer than two intensities or arrays of different shapes;
        counts that are not counts (k outside 0..n, n < 1); intensities not finite, or at
        or below 0 for a Weibull; a guess rate and lapse bound that leave ψ no range.
    """
    _check_function(function)
    x, k, n = (np.asarray(a, dtype=float) for a in (x, k, n))
    if x.shape != k.shape or x.shape != n.shape or x.ndim != 1 or x.size < 2:
        raise ValueError(f"needs trials at two intensities at least, in arrays of one "
                         f"shape; got x {x.shape}, k {k.shape}, n {n.shape}")
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(n))) or np.any(n < 1) \
            or np.any(k < 0) or np.any(k > n) or not np.all(np.isfinite(x)):
        raise ValueError("k must lie in 0..n with n ≥ 1 at finite intensities")
    if function == "weibull" and np.any(x <= 0):
        raise ValueError("a Weibull is fitted to intensities above 0 only")
    if not 0 < guess < 1 or not 0 <= lapse_max < 1 - guess:
        raise ValueError(f"guess {guess:g} and lapse_max {lapse_max:g} leave no range")
    return x, k, n


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
    x, k, n = _check_counts(function, x, k, n, guess, lapse_max)
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
                     gof_samples: int = 199, seed: int = 0, interval: str = "posterior",
                     width_prior: str = "ln-w") -> dict:
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
    interval : {'posterior', 'profile'}
        Which threshold and interval are stated: the posterior median with the central
        credible interval (the default), or the maximum-likelihood threshold with its
        profile-likelihood interval (kept for comparison). Coverage on adaptive data is
        measured (``hapticlab bench thresholds``) for one configuration only: Weibull
        observers fitted with a Weibull, criterion 0.75, ``lapse_max`` 0.06, a 3-down/1-up
        staircase and QUEST+. There the 95 % credible interval held the truth 95.5 % and
        97.0 % of the time, the profile interval 92.5 % and 87.5 %; other functions,
        criteria and lapse bounds have no coverage figure.
    width_prior : {'ln-w', 'psignifit'}
        The width's prior for ``interval="posterior"`` (:func:`threshold_posterior`).

    Returns
    -------
    dict
        ``function``, ``criterion``, ``interval``, ``threshold`` [units] with ``ci_low``
        and ``ci_high`` (``ci_note`` says where an end was extrapolated beyond the
        intensities tested, or why it is not stated: None), ``ci_level``,
        ``threshold_ml`` (the maximum-likelihood function's threshold, whatever
        ``interval``), ``p_never`` (the posterior probability that ψ never reaches the
        criterion; None for ``profile``), ``m`` and ``width``
        (psignifit's threshold and width of F, on ln x for the Weibull), ``alpha_w`` and
        ``beta`` (the Weibull's α, β; None otherwise), ``slope`` (dψ/dx of the
        maximum-likelihood function at ``threshold_ml`` [1/units]; ``m``, ``width``,
        ``lapse``, ``alpha_w`` and ``beta`` are that function's too), ``lapse``,
        ``lapse_max``, ``guess``, ``deviance``, ``gof_p`` (bootstrap; None without
        samples), ``gof_samples``, ``seed``, ``n_trials``, ``n_levels``, ``loglik``.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.repeat([0.02, 0.05, 0.1, 0.2, 0.4], 20)
    >>> k = np.concatenate([np.r_[np.ones(n), np.zeros(20 - n)] for n in (10, 12, 15, 19, 20)])
    >>> r = psychometric_fit(x, k, gof_samples=0)
    >>> round(r["threshold"], 3), round(r["threshold_ml"], 3), r["criterion"], r["n_trials"]
    (0.098, 0.1, 0.75, 100)
    >>> round(r["ci_low"], 3), round(r["ci_high"], 3), r["interval"]
    (0.058, 0.154, 'posterior')
    """
    if interval not in ("posterior", "profile"):
        raise ValueError(f"interval must be 'posterior' or 'profile', got {interval!r}")
    lv = levels(x, correct)
    fit = fit_psychometric(lv["x"], lv["k"], lv["n"], function, guess, lapse_max)
    t = fit.threshold(criterion)
    never = None
    if interval == "profile":
        lo, hi, note = _profile_ci(fit, lv["x"].to_numpy(), lv["k"].to_numpy(),
                                   lv["n"].to_numpy(), criterion, lapse_max, alpha)
        stated = t if math.isfinite(t) else None
    else:
        post = threshold_posterior(lv["x"], lv["k"], lv["n"], function, guess, lapse_max,
                                   criterion, alpha, width_prior)
        stated, lo, hi, note, never = (post["median"], post["low"], post["high"],
                                       post["note"], post["never"])
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
    return {"function": function, "criterion": criterion, "interval": interval,
            "threshold": stated, "ci_low": lo, "ci_high": hi,
            "ci_level": 1 - alpha, "ci_note": note,
            "threshold_ml": t if math.isfinite(t) else None, "p_never": never,
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



def _prior_m(m, lo: float, hi: float):
    """The prior density of m (psignifit 4's): flat over the intensities tested [lo, hi],
    falling as a cosine to 0 at half their span beyond either end."""
    sp = hi - lo
    m = np.asarray(m, dtype=float)
    p = np.where((m > lo) & (m < hi), 1.0, 0.0)
    left = (m >= lo - sp / 2) & (m <= lo)
    right = (m >= hi) & (m <= hi + sp / 2)
    p = np.where(left, (1 + np.cos(2 * np.pi * (lo - m) / sp)) / 2, p)
    return np.where(right, (1 + np.cos(2 * np.pi * (m - hi) / sp)) / 2, p)


#: the width priors :func:`threshold_posterior` offers: psignifit 4's shape over ln w (the
#: default) or over w, as psignifit 4 has it (kept to reproduce why the default departs)
WIDTH_PRIORS = ("ln-w", "psignifit")


def _prior_w(w, wmin: float, wmax: float, width_prior: str = "ln-w"):
    """The prior density of the width w (F from 0.05 to 0.95): psignifit 4's shape — flat
    from twice the finest step between the intensities tested to their span, falling as a
    cosine to 0 at that step and at three times the span — over ln w (``"ln-w"``: the shape
    divided by w), or over w as psignifit's own default (``"psignifit"``)."""
    w = np.asarray(w, dtype=float)
    p = np.where((w > 2 * wmin) & (w < wmax), 1.0, 0.0)
    left = (w >= wmin) & (w <= 2 * wmin)
    right = (w >= wmax) & (w <= 3 * wmax)
    p = np.where(left, (1 - np.cos(np.pi * (w - wmin) / wmin)) / 2, p)
    p = np.where(right, (1 + np.cos(np.pi / 2 * (w - wmax) / wmax)) / 2, p)
    return p if width_prior == "psignifit" else p / w


#: the lapse rate's prior, psignifit 4's Beta(1, 10), cut at the bound
LAPSE_PRIOR = (1.0, 10.0)
_GRID = (120, 60, 13)  # m × w × λ points of the fine grid
_COARSE = (40, 30, 4)
_REACH = (60, 13)  # w × λ points of the grid an open end is tested on


def _grid_posterior(function, x, k, n, guess, ms, ws, lams, lo, hi, wmin, width_prior):
    """The log posterior (up to a constant) and log likelihood on ms × ws × lams, the w
    grid geometric (a point's mass is its density times w)."""
    M, W, L = np.meshgrid(ms, ws, lams, indexing="ij")
    ll = -_nll(function, x, k, n, M, W, guess, L)
    with np.errstate(divide="ignore"):
        lp = ll + np.log(_prior_m(M, lo, hi)) \
            + np.log(_prior_w(W, wmin, hi - lo, width_prior) * W) \
            + stats.beta.logpdf(L, *LAPSE_PRIOR)
    return lp, ll, M, W, L


def _threshold_at(function, m, w, lam, guess: float, criterion: float):
    """The threshold at ``criterion`` on F's axis for (m, w, λ) (broadcast), and where ψ
    reaches the criterion at all (elsewhere the threshold is meaningless)."""
    f = (criterion - guess) / (1.0 - guess - lam)
    reach = (f > 0) & (f < 1)
    t = _loc(function, m, w) + _scale(function, w) * _ppf_array(function,
                                                                np.where(reach, f, 0.5))
    return t, reach


def _loglik_held(function, x, k, n, guess, lapse_max, criterion, t, wmin, wmax):
    """The largest log likelihood of the answers with the threshold at ``criterion`` held
    at ``t`` (on F's axis), the width and lapse free over the priors' support (a grid of
    :data:`_REACH` points; m follows from the three)."""
    ws = np.geomspace(wmin, 3 * wmax, _REACH[0])
    lams = np.linspace(0.0, lapse_max, _REACH[1]) if lapse_max > 0 else np.array([0.0])
    W, L = np.meshgrid(ws, lams, indexing="ij")
    f = (criterion - guess) / (1.0 - guess - L)
    ok = (f > 0) & (f < 1)  # λ for which ψ reaches the criterion at all
    if not ok.any():
        return -np.inf
    s = _scale(function, W[ok])
    M = t - s * _ppf_array(function, f[ok]) + s * _ppf(function, 0.5)
    return float(np.max(-_nll(function, x, k, n, M, W[ok], guess, L[ok])))


def threshold_posterior(x, k, n, function: str = "weibull", guess: float = 0.5,
                        lapse_max: float = 0.06, criterion: float = 0.75,
                        alpha: float = 0.05, width_prior: str = "ln-w") -> dict:
    """The posterior of the threshold at ``criterion`` on a grid over m, w and λ, and its
    central 1 − ``alpha`` credible interval (module docstring).

    Parameters
    ----------
    x, k, n : array-like
        Intensities [units], right answers and trials at each (:func:`levels`).
    function, guess, lapse_max, criterion, alpha
        As :func:`psychometric_fit`.
    width_prior : {'ln-w', 'psignifit'}
        The width's prior: psignifit 4's shape flat in ln w (the default), or flat in w as
        psignifit 4's own default (for comparison: on adaptive data it pulls the threshold
        low, :doc:`/explanation/psychometric-fits`).

    Returns
    -------
    dict
        ``median`` [units] (None where the function more probably never reaches the
        criterion), ``low`` and ``high`` (None where the answers do not bound that side or
        the criterion may never be reached), ``note`` (why an end is None, or that it lies
        beyond the intensities tested), ``never`` (the posterior probability that ψ never
        reaches the criterion).

    Raises
    ------
    ValueError
        Data :func:`fit_psychometric` would refuse, fewer than two distinct intensities, a
        criterion or ``alpha`` outside (0, 1), or an unknown ``width_prior``.
    """
    x, k, n = _check_counts(function, x, k, n, guess, lapse_max)
    if not 0 < criterion < 1 or not 0 < alpha < 1:
        raise ValueError(f"criterion {criterion:g} and alpha {alpha:g} must lie in (0, 1)")
    if width_prior not in WIDTH_PRIORS:
        raise ValueError(f"width_prior must be one of {', '.join(WIDTH_PRIORS)}, "
                         f"got {width_prior!r}")
    u = _axis(function, x)
    lv = np.unique(_round_sig(u))
    if lv.size < 2:
        raise ValueError(f"needs trials at two intensities at least, got {lv.size}")
    lo, hi = float(lv[0]), float(lv[-1])
    sp = hi - lo
    wmin = float(np.min(np.diff(lv)))
    lams = np.linspace(0.0, lapse_max, _GRID[2]) if lapse_max > 0 else np.array([0.0])
    # a coarse pass over the priors' support, then a fine grid where the posterior is
    ms = np.linspace(lo - sp / 2, hi + sp / 2, _COARSE[0])
    ws = np.geomspace(wmin, 3 * sp, _COARSE[1])
    lp, ll, *_ = _grid_posterior(function, x, k, n, guess, ms, ws,
                                 np.linspace(0.0, lapse_max, _COARSE[2]), lo, hi, wmin,
                                 width_prior)
    top = float(np.max(ll))
    keep = lp >= np.max(lp) - 15.0
    im, iw = np.flatnonzero(keep.any(axis=(1, 2))), np.flatnonzero(keep.any(axis=(0, 2)))
    ms = np.linspace(ms[max(im[0] - 1, 0)], ms[min(im[-1] + 1, ms.size - 1)], _GRID[0])
    ws = np.geomspace(ws[max(iw[0] - 1, 0)], ws[min(iw[-1] + 1, ws.size - 1)], _GRID[1])
    lp, ll, M, W, L = _grid_posterior(function, x, k, n, guess, ms, ws, lams, lo, hi, wmin,
                                      width_prior)
    top = max(top, float(np.max(ll)))
    post = np.exp(lp - np.max(lp))
    post /= post.sum()
    f = (criterion - guess) / (1.0 - guess - L)
    t, reach = _threshold_at(function, M, W, L, guess, criterion)
    order = np.argsort(np.where(reach, t, np.inf), axis=None)
    t_s, p_s = t.ravel()[order], post.ravel()[order]
    fin = reach.ravel()[order]
    never = float(p_s[~fin].sum())
    below = f.max() <= 0  # the criterion is at or under the guess rate everywhere
    c = np.cumsum(p_s[fin]) - p_s[fin] / 2

    def quantile(q):
        if below or q > 1 - never:
            return None
        return float(_back(function, np.interp(q, c, t_s[fin])))

    med, low, high = quantile(0.5), quantile(alpha / 2), quantile(1 - alpha / 2)
    notes = []
    if below:
        notes.append("no threshold: the criterion is at or below the guess rate")
    elif med is None:
        notes.append("no threshold: the function more probably never reaches the criterion")
        low = high = None
    elif high is None:
        notes.append("the upper end is not stated: the function may never reach the "
                     "criterion (a lapse rate above 1 − criterion is credible)")
    # a side is open when the answers fit as well (within the χ²₁ cut) with the threshold
    # at the criterion as far out as the prior reaches on that side (half the span of the
    # intensities tested beyond them, where m's prior ends): the data do not bound it
    # there, the prior would, and an end set by the prior is not stated as a number
    cut = stats.chi2.ppf(1 - alpha, 1) / 2.0
    for side, end, edge, far in (("lower", low, float(np.min(x)), lo - sp / 2),
                                 ("upper", high, float(np.max(x)), hi + sp / 2)):
        if end is None:
            continue
        if top - _loglik_held(function, x, k, n, guess, lapse_max, criterion, far, wmin,
                              sp) < cut:
            notes.append(f"the {side} end is not bounded by the answers: thresholds as far "
                         f"as the prior reaches (half the span of the intensities tested "
                         f"beyond the {'lowest' if side == 'lower' else 'highest'}) fit "
                         "them about as well as the best")
            if side == "lower":
                low = None
            else:
                high = None
            if med is not None and ((side == "lower" and med < edge) or
                                    (side == "upper" and med > edge)):
                # the median itself is the prior's: the answers put the threshold beyond
                # the intensities tested and do not say how far
                med = None
                notes.insert(0, f"no threshold: the answers put it "
                                f"{'below the lowest' if side == 'lower' else 'above the highest'}"
                                " intensity tested, and do not say how far")
        elif (side == "lower" and end < edge) or (side == "upper" and end > edge):
            notes.append(f"the {side} end is extrapolated beyond the intensities tested")
    return {"median": med, "low": low, "high": high, "note": "; ".join(notes),
            "never": never}
