"""Parametric tests of repeated measures: the repeated-measures ANOVA with sphericity, paired
t-tests and equivalence tests (TOST)."""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pandas as pd
from scipy import special

from ._base import MISSING, RTOL, StatsError, _as_list, _check_columns, _tol
from .effsize import np2_ci
from .multicomp import p_adjust
from .shaping import _complete, wide_means

__all__ = ["pairwise_ttests", "rm_anova", "equivalence_ttests"]


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
