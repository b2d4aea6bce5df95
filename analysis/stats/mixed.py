"""A linear mixed model of trial-level ratings: random intercept per participant, REML, type-
III Wald tests."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
from scipy import special

from ._base import RTOL, StatsError, _anchor, _check_columns, _check_values

__all__ = ["mixed_oneway"]


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
