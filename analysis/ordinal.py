"""Cumulative-link mixed model of ordinal ratings: logit link, a random intercept per
participant, maximum likelihood by adaptive Gauss–Hermite quadrature (R's
``ordinal::clmm(..., nAGQ = 20)`` is the reference).

A fixed-effects cumulative-link model (one intercept per participant) is biased at 8
ratings per participant and sample (the incidental-parameter problem: its coefficients
grow away from 0); a random intercept is the model the design asks for.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import optimize, special

from .stats import StatsError
from .stats._base import _check_columns, _check_values

__all__ = ["ordinal_mixed", "MAX_ROWS"]

#: Rows above which the fit is refused before it allocates: each likelihood evaluation
#: holds rows × nodes doubles several times over, and the optimiser needs ~10³ of them.
MAX_ROWS = 200_000
#: beyond this many log-odds [logits] an estimate has run off rather than converged: the
#: ratings separate the levels (every rating of one above the other's), the likelihood has
#: no maximum in that direction, and a Wald SE or CI there would be a number without a
#: meaning (an odds ratio of e^15 ≈ 3 million)
DIVERGED_LOGITS = 15.0
#: quadrature nodes per participant (adaptive: centred and scaled on each posterior mode)
NODES = 20


def _cell_probs(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """F(A) − F(B) for the logistic F, computed on the side that keeps its digits."""
    hi = B > 0
    return np.where(hi, special.expit(-B) - special.expit(-A),
                    special.expit(A) - special.expit(B))


class _Model:
    """−log-likelihood of a cumulative logit model with a random intercept."""

    def __init__(self, y: np.ndarray, X: np.ndarray, g: np.ndarray, n_cat: int):
        self.y, self.X, self.g, self.K = y, X, g, n_cat
        self.n_groups = int(g.max()) + 1
        self.x, self.w = np.polynomial.hermite.hermgauss(NODES)

    def unpack(self, par: np.ndarray):
        K = self.K
        theta = np.cumsum(np.concatenate([[par[0]], np.exp(par[1:K - 1])]))
        beta = par[K - 1:K - 1 + self.X.shape[1]]
        sigma = math.exp(par[-1])
        return theta, beta, sigma

    def _bounds(self, theta, beta):
        eta = self.X @ beta if self.X.shape[1] else np.zeros(self.y.size)
        t = np.concatenate([[-np.inf], theta, [np.inf]])
        return t[self.y + 1] - eta, t[self.y] - eta  # upper and lower cut, per row

    def _derivs(self, a, b, u):
        """Σ per group of ℓ, ℓ', ℓ'' (in u) at each row's group's u."""
        A, B = a - u[self.g], b - u[self.g]
        p = np.maximum(_cell_probs(A, B), 1e-300)
        fA = np.where(np.isfinite(A), special.expit(A) * special.expit(-A), 0.0)
        fB = np.where(np.isfinite(B), special.expit(B) * special.expit(-B), 0.0)
        dA = np.where(np.isfinite(A), fA * (1 - 2 * special.expit(A)), 0.0)
        dB = np.where(np.isfinite(B), fB * (1 - 2 * special.expit(B)), 0.0)
        d1 = -(fA - fB) / p
        d2 = (dA - dB) / p - d1 ** 2
        n = self.n_groups
        return (np.bincount(self.g, np.log(p), n), np.bincount(self.g, d1, n),
                np.bincount(self.g, d2, n))

    def _modes(self, a, b, s2):
        """Each participant's posterior mode of u and the curvature scale there."""
        u = getattr(self, "_u", None)
        if u is None or not np.isfinite(u).all():
            u = np.zeros(self.n_groups)
        for _ in range(200):  # Newton, each step at most 1 logit: the log-posterior is
            _l, d1, d2 = self._derivs(a, b, u)  # concave, so clipped steps still converge
            step = np.clip((d1 - u / s2) / (d2 - 1 / s2), -1.0, 1.0)
            u = u - step
            if np.max(np.abs(step)) < 1e-10:
                break
        if not np.isfinite(u).all():
            self._u = None
            raise FloatingPointError("a participant's posterior mode is not finite")
        _l, _d1, d2 = self._derivs(a, b, u)
        curvature = 1 / s2 - d2  # > 0 where the log-posterior is concave, as it must be
        if not np.all(curvature > 0):  # rounding at far-out parameters: not a point to use
            self._u = None
            raise FloatingPointError("a participant's posterior has no curvature at its mode")
        self._u = u
        return u, 1.0 / np.sqrt(curvature)

    def nll(self, par: np.ndarray) -> tuple[float, np.ndarray]:
        """−log L and its gradient (the quadrature's nodes held where this call put them,
        which moves the value by less than the quadrature's own error)."""
        theta, beta, sigma = self.unpack(par)
        K, P = self.K, self.X.shape[1]
        if not np.all(np.isfinite(theta)) or not 1e-8 < sigma < 1e3:
            return np.inf, np.zeros(par.size)
        a, b = self._bounds(theta, beta)
        s2 = sigma * sigma
        try:
            u, s = self._modes(a, b, s2)
        except FloatingPointError:
            return np.inf, np.zeros(par.size)
        uq = u[:, None] + math.sqrt(2.0) * s[:, None] * self.x[None, :]  # groups × nodes
        A, B = a[:, None] - uq[self.g], b[:, None] - uq[self.g]  # rows × nodes
        p = np.maximum(_cell_probs(A, B), 1e-300)
        fA = np.where(np.isfinite(A), special.expit(A) * special.expit(-A), 0.0)
        fB = np.where(np.isfinite(B), special.expit(B) * special.expit(-B), 0.0)
        n = self.n_groups
        ll = np.stack([np.bincount(self.g, np.log(p[:, q]), n) for q in range(NODES)], 1)
        logs = (ll - uq ** 2 / (2 * s2) - math.log(sigma) - 0.5 * math.log(2 * math.pi)
                + self.x[None, :] ** 2 + np.log(self.w)[None, :])
        m = logs.max(axis=1, keepdims=True)
        e = np.exp(logs - m)
        tot = e.sum(axis=1, keepdims=True)
        value = float((m[:, 0] + np.log(tot[:, 0]) + np.log(math.sqrt(2.0) * s)).sum())
        pi = e / tot  # each node's share of its participant's likelihood
        wr = pi[self.g]  # rows × nodes
        gA = (wr * fA / p).sum(axis=1)  # Σ_q π ∂ℓ/∂(upper cut)
        gB = (wr * fB / p).sum(axis=1)
        d_theta = (np.bincount(np.clip(self.y, 0, K - 2), np.where(self.y < K - 1, gA, 0), K - 1)
                   - np.bincount(np.clip(self.y - 1, 0, K - 2), np.where(self.y > 0, gB, 0),
                                 K - 1))
        d_beta = -(self.X * (gA - gB)[:, None]).sum(axis=0) if P else np.zeros(0)
        d_logsig = float((pi * (uq ** 2 / s2 - 1.0)).sum())
        inc = np.exp(par[1:K - 1])
        d_inc = np.array([d_theta[k:].sum() for k in range(1, K - 1)]) * inc
        grad = np.concatenate([[d_theta.sum()], d_inc, d_beta, [d_logsig]])
        return -value, -grad

    def start(self) -> np.ndarray:
        cum = np.cumsum(np.bincount(self.y, minlength=self.K))[:-1] / self.y.size
        theta = special.logit(np.clip(cum, 1e-3, 1 - 1e-3))
        inc = np.log(np.maximum(np.diff(theta), 1e-3))
        return np.concatenate([[theta[0]], inc, np.zeros(self.X.shape[1]), [math.log(0.5)]])

    def fit(self):
        """L-BFGS-B from moment starts (its first step is scaled to the gradient, where
        BFGS' unit step leaves the likelihood's finite region); converged when L-BFGS-B
        says so (gradient below 1e-7 or no relative decrease left at 1e-15) or the gradient
        is below 1e-4 per parameter."""
        self._u = None
        x0 = self.start()
        bounds = ([(None, None)] + [(-12.0, 6.0)] * (self.K - 2)  # log increments
                  + [(None, None)] * self.X.shape[1] + [(-12.0, 6.0)])  # log σ
        res = optimize.minimize(self.nll, x0, jac=True, method="L-BFGS-B", bounds=bounds,
                                options={"gtol": 1e-7, "ftol": 1e-15, "maxiter": 5000})
        res.converged = bool(np.isfinite(res.fun)
                             and (res.success or np.max(np.abs(res.jac)) < 1e-4))
        return res


def ordinal_mixed(data: pd.DataFrame, dv: str, within: str, subject: str) -> pd.DataFrame:
    """Cumulative-link (proportional-odds, logit) mixed model of trial-level ratings on the
    levels of ``within``, with a random intercept per subject, and the likelihood-ratio
    test of ``within``.

    Parameters
    ----------
    data : DataFrame (long format, one row per rating)
    dv, within, subject : column names (``dv`` holds the ratings, in scale points)

    Returns
    -------
    DataFrame, one row
        ``Source``, ``n_subjects``, ``n_obs``, ``categories`` (rating values used), ``lr``
        (likelihood-ratio χ²), ``dof``, ``p_unc``, ``sd_subject`` (random-intercept SD, logit
        scale), ``loglik``, ``converged``. ``attrs["thresholds"]`` and ``attrs["fixed"]``:
        estimates with SEs and 95 % Wald CIs (coefficients of each level against the first,
        on the logit scale: positive means higher ratings); an estimate beyond
        :data:`DIVERGED_LOGITS`, or one whose SE is undefined, has None there and a
        ``note`` saying why.

    Raises
    ------
    StatsError
        Fewer than 3 rating values, 2 subjects or 2 levels; more than :data:`MAX_ROWS`
        rows (refused before allocating); or a fit that does not converge.

    Notes
    -----
    P(Y ≤ c | u) = logistic(θ_c − x β − u), u ~ N(0, σ²); each participant's integral over
    u by 20-node Gauss–Hermite quadrature centred on its posterior mode (as clmm's
    ``nAGQ``); the thresholds are kept in order by optimising θ₁ and log increments.
    """
    _check_columns(data, [dv, within, subject])
    _check_values(data, dv, [within, subject])
    d = data[[dv, within, subject]].copy()
    d[dv] = pd.to_numeric(d[dv], errors="coerce")
    d = d.dropna()
    if len(d) > MAX_ROWS:
        raise StatsError(f"the ordinal mixed model is limited to {MAX_ROWS:,} ratings on this "
                         f"machine (memory and time grow with rows × {NODES} nodes); the "
                         f"data have {len(d):,}: analyse a subset, or use the ANOVA and the "
                         "linear mixed model, which scale")
    cats = np.sort(d[dv].unique())
    if len(cats) < 3:
        raise StatsError(f"an ordinal model needs at least 3 distinct values of {dv}; the "
                         f"data use {len(cats)}")
    levels = list(dict.fromkeys(d[within]))
    if d[subject].nunique() < 2 or len(levels) < 2:
        raise StatsError(f"an ordinal model needs at least 2 subjects and 2 levels of "
                         f"{within!r}")
    y = np.searchsorted(cats, d[dv].to_numpy())
    g = pd.factorize(d[subject])[0]
    li = pd.Categorical(d[within], categories=levels).codes
    X = (li[:, None] == np.arange(1, len(levels))[None, :]).astype(float)
    full = _Model(y, X, g, len(cats))
    reduced = _Model(y, np.zeros((len(y), 0)), g, len(cats))
    rf, rr = full.fit(), reduced.fit()
    if not (rf.converged and rr.converged):
        raise StatsError(f"the ordinal mixed model did not converge ({rf.message}; "
                         f"{rr.message})")
    if not (np.isfinite(rf.fun) and np.isfinite(rr.fun)):
        raise StatsError("the ordinal mixed model could not be fitted (the likelihood is "
                         "not finite at any tried parameter)")
    lr = max(0.0, 2.0 * (rr.fun - rf.fun))
    dof = len(levels) - 1
    theta, beta, sigma = full.unpack(rf.x)
    out = pd.DataFrame([{"Source": within, "n_subjects": int(g.max() + 1),
                         "n_obs": int(len(y)), "categories": int(len(cats)), "lr": lr,
                         "dof": dof, "p_unc": float(special.chdtrc(dof, lr)),
                         "sd_subject": sigma, "loglik": -float(rf.fun),
                         "converged": True}])
    se = _wald_se(full, rf.x)
    z = float(special.ndtri(0.975))
    K = len(cats)
    th_se = _threshold_se(full, rf.x)
    out.attrs["thresholds"] = [
        {"between": f"{cats[i]:g}|{cats[i + 1]:g}", **_wald(t, s, None)}
        for i, (t, s) in enumerate(zip(theta, th_se, strict=True))]
    out.attrs["fixed"] = [
        {"term": f"{within}[{lv}]", **_wald(b, s, z)}
        for lv, b, s in zip(levels[1:], beta, se[K - 1:K - 1 + len(beta)], strict=True)]
    diverged = [r for r in (*out.attrs["thresholds"], *out.attrs["fixed"])
                if str(r.get("note", "")).startswith("diverged")]
    if diverged:
        out["note"] = (f"{len(diverged)} estimate(s) diverged (the ratings separate some "
                       "levels): the likelihood-ratio test compares the likelihoods' suprema "
                       "and is still defined; those coefficients and their SEs are not")
    return out


def _wald(estimate: float, se: float, z: float | None) -> dict:
    """An estimate with its SE (and, given ``z``, its Wald CI); where either is not defined,
    None and a ``note`` saying why, never a number that means nothing."""
    row = {"estimate": float(estimate), "se": float(se)}
    if z is not None:
        row.update(ci_low=float(estimate - z * se), ci_high=float(estimate + z * se))
    why = None
    if abs(estimate) > DIVERGED_LOGITS:
        why = (f"diverged (beyond ±{DIVERGED_LOGITS:g} log-odds: the ratings separate these "
               "levels, so the likelihood has no maximum here): no SE or CI")
    elif not math.isfinite(se):
        why = "no SE or CI: the likelihood's curvature is not positive at the fit"
    if why is not None:
        row.update({k: None for k in row if k != "estimate"}, note=why)
    return row


def _threshold_se(model: _Model, par: np.ndarray) -> np.ndarray:
    """Standard errors of the thresholds θ (delta method through θ₁ and log increments)."""
    K = model.K
    cov = _cov(model, par)
    J = np.zeros((K - 1, par.size))  # ∂θ_c / ∂par
    J[:, 0] = 1.0
    for c in range(1, K - 1):
        J[c, 1:c + 1] = np.exp(par[1:c + 1])
    return _sd(np.diag(J @ cov @ J.T))


def _cov(model: _Model, par: np.ndarray) -> np.ndarray:
    """Inverse of the numerical Hessian of −log L (NaN where it is singular)."""
    from statsmodels.tools.numdiff import approx_fprime

    H = approx_fprime(par, lambda x: model.nll(x)[1], centered=True)
    H = (H + H.T) / 2
    try:
        np.linalg.cholesky(H)  # a maximum: positive definite, else no covariance exists
        return np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return np.full((par.size, par.size), np.nan)


def _sd(variance: np.ndarray) -> np.ndarray:
    """√variance, NaN where the variance is not positive (it was clipped to 0 and printed
    as an SE of 0)."""
    return np.sqrt(np.where(variance > 0, variance, np.nan))


def _wald_se(model: _Model, par: np.ndarray) -> np.ndarray:
    """Standard errors of the parameters as optimised (NaN where the Hessian is not
    positive definite)."""
    return _sd(np.diag(_cov(model, par)))
