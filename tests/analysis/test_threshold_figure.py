"""The threshold figure (review final item 9): the curves are the maximum-likelihood
functions, which meet the criterion at ``threshold_ml``; the stated thresholds, posterior
medians, are ticks on the criterion with their credible intervals, and the dashed line is
their mean, as in the report's table. Unit tier: one figure from hand-made results."""

import numpy as np
import pandas as pd
import pytest

from analysis import plots
from analysis.psychometric import psychometric_fit

X = np.repeat([0.02, 0.05, 0.1, 0.2, 0.4], 20)
K = np.concatenate([np.r_[np.ones(c), np.zeros(20 - c)] for c in (10, 12, 15, 19, 20)])


def test_the_figure_draws_the_stated_thresholds_beside_the_ml_curves(monkeypatch, tmp_path):
    x, k = X, K
    fits = []
    for pid, shift in (("p1", 1.0), ("p2", 1.3)):
        r = psychometric_fit(x * shift, k, gof_samples=0)
        fits.append({"participant": pid, "track": "t", **{key: r[key] for key in (
            "threshold", "ci_low", "ci_high", "threshold_ml", "m", "width", "lapse")}})
    stated = [f["threshold"] for f in fits]
    result = {"fits": fits, "function": "weibull", "criterion": 0.75, "units": "log10",
              "parameter": "frequency", "group": [{"track": "t",
                                                    "threshold_mean": float(np.mean(stated))}]}
    data = pd.DataFrame({"design_key": "d", "phase": "ph", "valid": True, "track": "t",
                         "participant": np.repeat(["p1", "p2"], x.size), "session": "s",
                         "trial_index": np.tile(np.arange(x.size), 2), "state": "",
                         "intensity": np.r_[x, x * 1.3], "correct": np.r_[k, k]})
    drawn = []
    monkeypatch.setattr(plots, "_save", lambda fig, out, name: drawn.append(fig) or [name])
    plots.psychometric({"id": "a", "design_key": "d", "phase": "ph", "result": result},
                       data, tmp_path)
    ax = drawn[0].axes[0]
    ticks = sorted(float(ln.get_xdata()[0]) for ln in ax.get_lines()
                   if ln.get_marker() == "|")
    assert ticks == pytest.approx(sorted(stated))
    dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
    assert float(dashed[0].get_xdata()[0]) == pytest.approx(np.mean(stated))
    # the stated threshold is not where the ML curve meets the criterion: both are drawn
    assert all(abs(f["threshold"] / f["threshold_ml"] - 1) > 1e-3 for f in fits)
    plots._plt().close("all")
