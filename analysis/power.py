"""Monte-Carlo power and precision: how many participants and repetitions a study needs.

Model of one rating: y = μ_sample + b_subject + u_subject×sample + e_trial, with
u ~ N(0, sd_interaction²) and e ~ N(0, sd_trial²). A participant's mean over r repetitions
of a sample then has within-subject noise sd_interaction² + sd_trial²/r (the subject bias b
cancels in paired comparisons and in z-scores), so for each (participants n, repetitions r)
the simulation draws ``experiments`` studies at once (vectorised) and reports

* ``ci_halfwidth``: median half-width of the 95 % CI of a sample's mean rating (precision);
* ``power``: share of studies whose paired t-test of the key contrast (``effect`` scale
  points) is significant at alpha, Bonferroni-adjusted over ``comparisons`` pairs (the
  strictest step of Holm's procedure).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

__all__ = ["power_table", "variance_components"]


def power_table(subjects=range(5, 31, 5), reps=range(1, 6), effect: float = 1.0,
                sd_trial: float = 0.9, sd_interaction: float = 0.5, sd_subject: float = 0.8,
                alpha: float = 0.05, comparisons: int = 55, experiments: int = 10_000,
                seed: int = 0) -> pd.DataFrame:
    """Power and precision for every (subjects, reps) cell.

    Returns
    -------
    DataFrame: ``subjects``, ``reps``, ``power``, ``ci_halfwidth`` [scale points],
    ``experiments``.
    """
    rng = np.random.default_rng(seed)
    rows = []
    a = alpha / max(1, comparisons)
    for n in subjects:
        for r in reps:
            # per-subject means of two samples (paired) over r repetitions
            sd_mean = np.sqrt(sd_interaction ** 2 + sd_trial ** 2 / r)
            d = rng.normal(effect, np.sqrt(2) * sd_mean, size=(experiments, n))
            t = d.mean(1) / (d.std(1, ddof=1) / np.sqrt(n))
            p = 2 * stats.t.sf(np.abs(t), n - 1)
            # precision of one sample's mean rating across subjects (subject bias included)
            m = rng.normal(0.0, np.sqrt(sd_subject ** 2 + sd_mean ** 2), size=(experiments, n))
            half = stats.t.ppf(0.975, n - 1) * m.std(1, ddof=1) / np.sqrt(n)
            rows.append({"subjects": n, "reps": r, "power": float((p < a).mean()),
                         "ci_halfwidth": float(np.median(half)), "experiments": experiments})
    return pd.DataFrame(rows)


def variance_components(data: pd.DataFrame, dv: str = "rating", sample: str = "sample",
                        subject: str = "participant", sd_trial: float | None = None
                        ) -> dict[str, float]:
    """Estimate sd_subject, sd_interaction and sd_trial from recorded ratings (method of
    moments on the two-way layout with repetitions).

    Parameters
    ----------
    sd_trial : float, optional
        The trial-to-trial SD [scale points], when the pilot cannot give it: with one
        rating per participant and sample (a factorial design rates each set once) trial
        noise and participant × sample noise are confounded.

    Raises
    ------
    ValueError
        Fewer than 2 participants with every sample, or no cell rated twice and no
        ``sd_trial`` given.
    """
    d = data[[subject, sample, dv]].dropna()
    cell = d.groupby([subject, sample], observed=True)[dv]
    if sd_trial is None:
        var = cell.var(ddof=1).dropna()
        if var.empty:
            raise ValueError("the trial-to-trial SD needs cells rated at least twice; this "
                             "pilot has one rating per participant and sample, so trial and "
                             "participant × sample noise cannot be told apart: give "
                             "--sd-trial, or use a pilot with repetitions")
        sd_trial = float(np.sqrt(var.mean()))
    reps = float(cell.size().mean())
    means = cell.mean().unstack(sample).dropna()  # participants with every sample
    if means.shape[0] < 2 or means.shape[1] < 2:
        raise ValueError("variance components need at least 2 participants with every "
                         "sample and 2 samples")
    m = means.to_numpy()
    n, k = m.shape
    resid = m - m.mean(1, keepdims=True) - m.mean(0, keepdims=True) + m.mean()
    # E[SS_resid / ((n−1)(k−1))] = sd_interaction² + sd_trial² / r
    var_int = max(0.0, float((resid ** 2).sum()) / ((n - 1) * (k - 1)) - sd_trial ** 2 / reps)
    # a participant's mean over the k samples carries (sd_int² + sd_trial²/r)/k of noise
    var_subj = float(m.mean(1).var(ddof=1)) - (var_int + sd_trial ** 2 / reps) / k
    sd_subject = float(np.sqrt(max(0.0, var_subj)))
    return {"sd_trial": sd_trial, "sd_interaction": float(np.sqrt(var_int)),
            "sd_subject": sd_subject}
