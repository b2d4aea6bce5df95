"""Monte-Carlo power and precision against their closed forms."""

import math
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from analysis.power import power_table


@pytest.mark.parametrize("n, r", [(10, 1), (20, 3), (30, 5)])
def test_power_matches_the_noncentral_t(n, r):
    """Paired t-test power = P(|T| > t_crit) for T ~ noncentral t(n − 1, δ·√n), with
    δ = effect / (√2·√(sd_int² + sd_trial²/r)); Monte-Carlo error of 10⁴ runs ≈ 0.005."""
    effect, sd_t, sd_i, alpha = 1.0, 0.9, 0.5, 0.05 / 55
    t = power_table([n], [r], effect, sd_trial=sd_t, sd_interaction=sd_i, alpha=0.05,
                    comparisons=55, experiments=10_000, seed=1).iloc[0]
    delta = effect / (math.sqrt(2) * math.sqrt(sd_i ** 2 + sd_t ** 2 / r))
    crit = stats.t.ppf(1 - alpha / 2, n - 1)
    nc = delta * math.sqrt(n)
    # lower tail written as the upper tail of −T: scipy 1.17's nct.cdf returns nan
    # far out in the left tail (n=30, nc≈6), while nct.sf stays finite there
    exact = stats.nct.sf(crit, n - 1, nc) + stats.nct.sf(crit, n - 1, -nc)
    assert math.isfinite(exact)
    assert t["power"] == pytest.approx(exact, abs=0.02)


def test_precision_matches_the_t_interval():
    """Median CI half-width ≈ t(0.975, n−1)·σ/√n with σ² = sd_subj² + sd_int² + sd_trial²/r
    (the median of the sample SD is a little below σ: tolerance 5 %)."""
    n, r = 15, 3
    row = power_table([n], [r], experiments=10_000, seed=2).iloc[0]
    sigma = math.sqrt(0.8 ** 2 + 0.5 ** 2 + 0.9 ** 2 / r)
    assert row["ci_halfwidth"] == pytest.approx(stats.t.ppf(0.975, n - 1) * sigma
                                                / math.sqrt(n), rel=0.05)


def test_more_people_and_repetitions_buy_power_and_precision():
    t = power_table([5, 15, 30], [1, 3, 5], experiments=4000, seed=3)
    g = t.pivot(index="subjects", columns="reps", values="power").to_numpy()
    h = t.pivot(index="subjects", columns="reps", values="ci_halfwidth").to_numpy()
    assert np.all(np.diff(g, axis=0) >= -0.02) and np.all(np.diff(g, axis=1) >= -0.02)
    assert np.all(np.diff(h, axis=0) < 0) and np.all(np.diff(h, axis=1) < 0)


@pytest.mark.integration
def test_power_cli():
    out = subprocess.run([sys.executable, "-m", "app", "power", "realism", "--subjects", "5..30",
                          "--reps", "1..5", "--json"], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    import json

    d = json.loads(out.stdout)
    assert d["comparisons"] == 55 and len(d["rows"]) == 6 * 5
    assert all(r["experiments"] == 10_000 for r in d["rows"])
    bad = subprocess.run([sys.executable, "-m", "app", "power", "realism", "--subjects", "x"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "--subjects" in bad.stderr
    unrated = subprocess.run([sys.executable, "-m", "app", "power", "identification"],
                             capture_output=True, text=True)
    assert unrated.returncode == 2 and "no analysed rating phase" in unrated.stderr


def test_variance_components_recover_known_sds():
    """Method of moments on a two-way layout drawn with known SDs (400 subjects × 11 samples
    × 3 repetitions; sampling error of each SD estimate is a few per cent)."""
    import pandas as pd

    from analysis.power import variance_components

    rng = np.random.default_rng(7)
    n, k, r = 400, 11, 3
    b = rng.normal(0, 0.8, n)[:, None, None]
    u = rng.normal(0, 0.5, (n, k))[:, :, None]
    y = np.arange(k)[None, :, None] * 0.1 + b + u + rng.normal(0, 0.9, (n, k, r))
    s, j, _ = np.indices(y.shape)
    d = pd.DataFrame({"participant": s.ravel(), "sample": j.ravel(), "rating": y.ravel()})
    d = d.drop(index=[0, 1, 2])  # one missing cell: that participant is left out, not NaN
    vc = variance_components(d)
    assert vc["sd_trial"] == pytest.approx(0.9, rel=0.03)
    assert vc["sd_interaction"] == pytest.approx(0.5, rel=0.1)
    assert vc["sd_subject"] == pytest.approx(0.8, rel=0.1)


@pytest.mark.parametrize("subjects, step, expected", [
    ("5,10,20", 5, [5, 10, 20]),  # a list is every count named, whatever --step says
    ("5..20", 5, [5, 10, 15, 20]),  # a range takes --step
    ("4..6", 1, [4, 5, 6]),
])
def test_power_command_takes_a_list_of_subjects_whole(subjects, step, expected, capsys):
    from app.cli import main

    assert main(["power", "realism", "--subjects", subjects, "--step", str(step), "--reps", "1",
                 "--experiments", "20", "--json"]) == 0
    import json

    assert [r["subjects"] for r in json.loads(capsys.readouterr().out)["rows"]] == expected


def test_power_command_refuses_a_step_below_one(capsys):
    from app.cli import main

    assert main(["power", "realism", "--subjects", "5..20", "--step", "0"]) == 2
    assert "--step" in capsys.readouterr().err
