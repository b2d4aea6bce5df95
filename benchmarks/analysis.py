"""``hapticlab bench analysis``: the realism analysis, vectorised, against per-test loops.

Data: a simulated realism study (9 participants × 11 samples × 3 ratings). Timed (median of
repeats, same process):

* ours: rm_anova (with sphericity) + pairwise_ttests (55 pairs, Holm) + 11 per-sample CIs;
* baseline: statsmodels ``AnovaRM`` + 55 × ``scipy.stats.ttest_rel`` + statsmodels
  ``multipletests`` + 11 × ``scipy.stats.t.interval`` — one call per test.

Also: ``hapticlab power`` style Monte-Carlo, 10⁴ experiments for one cell, timed.
"""

from __future__ import annotations

import itertools
import time

import numpy as np
import pandas as pd

from ._common import emit, median_time, print_table


def _study(seed: int = 0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(9):
        bias = rng.normal(0, 0.8)
        for j in range(11):
            for _ in range(3):
                rows.append({"participant": f"P{s}", "sample": f"s{j:02d}",
                             "rating": float(np.clip(np.round(4 + 0.25 * (j - 5) + bias
                                                              + rng.normal(0, 1)), 1, 7))})
    return pd.DataFrame(rows)


def ours(d: pd.DataFrame) -> None:
    from analysis import pairwise_ttests, rm_anova
    from analysis.stats import wide_means
    from analysis.study import mean_cis

    rm_anova(d, "rating", "sample", "participant")
    pairwise_ttests(d, "rating", "sample", "participant", "holm")
    mean_cis(wide_means(d, "rating", "sample", "participant")[0])


def baseline(d: pd.DataFrame) -> None:
    import warnings

    from scipy import stats
    from statsmodels.stats.anova import AnovaRM
    from statsmodels.stats.multitest import multipletests

    agg = d.groupby(["participant", "sample"], as_index=False)["rating"].mean()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        AnovaRM(agg, "rating", "participant", within=["sample"]).fit()
    wide = agg.pivot(index="participant", columns="sample", values="rating")
    ps = [stats.ttest_rel(wide[a], wide[b]).pvalue
          for a, b in itertools.combinations(wide.columns, 2)]
    multipletests(ps, method="holm")
    for c in wide.columns:
        x = wide[c]
        stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))


def main(args) -> int:
    from analysis.power import power_table

    d = _study()
    ours(d)
    baseline(d)  # warm both
    t_ours = median_time(lambda: ours(d), max(5, args.repeats))
    t_base = median_time(lambda: baseline(d), max(5, args.repeats))
    t0 = time.perf_counter()
    power_table(subjects=[9], reps=[3], experiments=10_000)
    t_power = time.perf_counter() - t0
    payload = {"ours_ms": t_ours * 1e3, "baseline_ms": t_base * 1e3, "ratio": t_base / t_ours,
               "power_1e4_experiments_ms": t_power * 1e3, "repeats": max(5, args.repeats)}
    if args.json:
        emit(payload, True)
        return 0
    print_table("analysis: realism study (ANOVA + 55 paired t-tests + 11 CIs), median",
                ["implementation", "ms", "ratio"],
                [("hapticlab (vectorised)", f"{t_ours * 1e3:.2f}", "1.0"),
                 ("per-test loop: statsmodels AnovaRM + scipy ttest_rel ×55 + t.interval ×11",
                  f"{t_base * 1e3:.2f}", f"{t_base / t_ours:.1f}× slower")])
    print(f"power: 10⁴ simulated experiments (9 participants, 3 repetitions): "
          f"{t_power * 1e3:.0f} ms")
    return 0
