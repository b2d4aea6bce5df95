"""Psychometric fits (issue 57, item 3) against psignifit 4 on the same data.

psignifit 4 (Schütt et al. 2016; PyPI ``psignifit``) is Bayesian: its MAP estimate equals
the maximum-likelihood fit when its priors are flat within the same bounds and its
overdispersion η is fixed at 0. Each reference value is computed in the test by the call
beside it::

    psignifit.psignifit(np.c_[levels, k, n], sigmoid=SIGMOID, experiment_type="2AFC",
                        fixed_parameters={"eta": 0.0}, bounds={"lambda": (0, 0.06)},
                        priors=FLAT (1 inside the bounds, 0 outside), estimate_type="MAP")

with the Weibull fitted by psignifit's ``weibull`` on ln x (as its documentation asks).
Tolerances, stated: thresholds at 75 % and 85 % and psignifit's threshold m within 0.2 %
(relative), widths within 0.5 %, lapse rates within 0.002; and our likelihood at least
psignifit's (ours is the maximum; where they differ it is psignifit's optimizer that
stopped short, by at most 0.3 % in width on these data).
"""

import math

import numpy as np
import pytest

from analysis.psychometric import (
    FUNCTIONS,
    LAPSE_PRIOR,
    deviance,
    fit_psychometric,
    levels,
    psi,
    psychometric_fit,
    threshold_posterior,
)

psignifit = pytest.importorskip("psignifit", reason="`make test` installs the test extra")

SIGMOID = {"weibull": "weibull", "normal": "norm", "logistic": "logistic"}


def _adaptive():
    """A 3-down/1-up staircase's trials as a simulated observer answered them (seed fixed;
    many intensities, few trials each, a lapse)."""
    from benchmarks.thresholds import _observer, _protocol, simulate_track

    run = simulate_track(_protocol("staircase"), _observer(7, 3), 11)
    return np.asarray(run["x"]), np.asarray(run["correct"])


def _blocks(levels_, counts, n):
    x = np.repeat(levels_, n)
    k = np.concatenate([np.r_[np.ones(c), np.zeros(n - c)] for c in counts])
    return x, k


DATA = {
    "adaptive": _adaptive,
    "blocks": lambda: _blocks([0.02, 0.05, 0.1, 0.2, 0.4], (10, 12, 15, 19, 20), 20),
    "lapses": lambda: _blocks([1.0, 2.0, 3.0, 4.0, 6.0, 8.0], (8, 8, 11, 13, 14, 14), 15),
}


def _box(lo, hi):
    return lambda v: ((np.asarray(v) >= lo) & (np.asarray(v) <= hi)).astype(float)


def _psignifit(x, k, function):
    lv = levels(x, k)
    u = np.log(lv["x"]) if function == "weibull" else lv["x"]
    span = float(u.max() - u.min())
    return psignifit.psignifit(
        np.c_[u, lv["k"], lv["n"]], sigmoid=SIGMOID[function], experiment_type="2AFC",
        fixed_parameters={"eta": 0.0}, bounds={"lambda": (0.0, 0.06)},
        priors={"threshold": _box(float(u.min()) - span, float(u.max()) + span),
                "width": _box(1e-9, 20 * span), "lambda": _box(0.0, 0.06)},
        estimate_type="MAP", verbose=False), lv


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # psignifit's log(0) at its grid's edge
@pytest.mark.parametrize("function", FUNCTIONS)
@pytest.mark.parametrize("data", sorted(DATA))
def test_the_fit_is_psignifits_map_under_flat_priors(data, function):
    x, k = DATA[data]()
    ref, lv = _psignifit(x, k, function)
    est = ref.get_parameter_estimate()
    back = math.exp if function == "weibull" else (lambda v: v)
    for crit in (0.75, 0.85):
        ours = psychometric_fit(x, k, function=function, criterion=crit, lapse_max=0.06,
                                gof_samples=0)
        theirs = back(float(ref.threshold(crit, return_ci=False)))
        assert ours["threshold_ml"] == pytest.approx(theirs, rel=2e-3), crit
        assert ours["criterion"] == crit
    assert ours["m"] == pytest.approx(est["threshold"], rel=2e-3, abs=1e-6)
    assert ours["width"] == pytest.approx(est["width"], rel=5e-3)
    assert ours["lapse"] == pytest.approx(est["lambda"], abs=2e-3)
    # ours is the maximum: psignifit's estimate is no likelier under the same model
    p_ref = psi(function, lv["x"], est["threshold"], est["width"], 0.5, est["lambda"])
    ll_ref = float(np.sum(lv["k"] * np.log(p_ref) + (lv["n"] - lv["k"]) * np.log1p(-p_ref)))
    assert ours["loglik"] >= ll_ref - 1e-6


def _their_width_prior(wmin, wmax):
    """psignifit's own width prior (psignifit._priors.width_prior) over w: the shape of
    ours, flat in ln w where psignifit's default is flat in w."""
    from psignifit._priors import width_prior

    return lambda w: width_prior(np.asarray(w, dtype=float), 0.05, wmin, wmax) / np.maximum(
        np.asarray(w, dtype=float), 1e-300)


def _their_threshold_posterior(x, k, width_prior="ln-w", criterion=0.75, steps=200):
    """psignifit's own posterior grid over (threshold m, width, λ), λ free in [0, 0.06]
    under its Beta(1, 10) prior as reports fit it, and from it the marginal of the threshold
    at ``criterion`` — t(m, w, λ) by psignifit's own sigmoid inverse — and its 2.5, 50 and
    97.5 % points (x units)::

        psignifit.psignifit(np.c_[ln levels, k, n], sigmoid="weibull",
                            experiment_type="2AFC", fixed_parameters={"eta": 0.0},
                            bounds={"lambda": (0.0, 0.06)},
                            priors={"width": psignifit's width prior / w},  # ln-w only
                            grid_steps={"threshold": 200, "width": 100,
                                        "lambda": 13},
                            debug=True).debug["posteriors"]

    The quantiles read the grid's point masses as the midpoints of their cells (the
    cumulated mass less half the point's own), as ours does; psignifit's own percentile
    interval (``confidence_intervals``) puts each point's whole mass at the point, which
    moves both ends down by half a step."""
    lv = levels(x, k)
    u = np.log(lv["x"].to_numpy())
    priors = {"width": _their_width_prior(float(np.min(np.diff(u))), float(np.ptp(u)))} \
        if width_prior == "ln-w" else None
    ref = psignifit.psignifit(
        np.c_[u, lv["k"], lv["n"]], sigmoid="weibull", experiment_type="2AFC",
        fixed_parameters={"eta": 0.0}, bounds={"lambda": (0.0, 0.06)}, priors=priors,
        grid_steps={"threshold": steps, "width": steps // 2, "lambda": 13}, debug=True,
        verbose=False)
    names = sorted(ref.parameter_values)
    grid = np.meshgrid(*(np.atleast_1d(ref.parameter_values[p]) for p in names),
                       indexing="ij")
    g = dict(zip(names, grid, strict=True))
    mass = ref.debug["posteriors"].reshape(grid[0].shape)
    t = ref.configuration.make_sigmoid().inverse(criterion, g["threshold"], g["width"],
                                                 0.5, g["lambda"])
    order = np.argsort(t, axis=None)
    ts, ps = t.ravel()[order], mass.ravel()[order] / mass.sum()
    c = np.cumsum(ps) - ps / 2
    return np.exp(np.interp([0.025, 0.5, 0.975], c, ts))


#: Relative tolerance of each quantile against psignifit's. A grid's quantile is off by up
#: to about half its step where the threshold takes one value per m (λ held at 0, t = m):
#: our fine grid's m step is 2.5–3.8 % of x on these data, and the λ = 0 comparison this
#: test replaces was 1.5 % apart at one end (ours 1.1 % off the converged value: our 120
#: m points against 480 — 0.05937 against 0.05881 on "blocks" — plus psignifit's own
#: percentile rule, half its step low). With λ free, λ and w spread the threshold between
#: the m points: ours moves at most 0.2 % from 120 to 480 m points, psignifit's at most
#: 0.05 % from 200 to 800 threshold steps, and the two differ by at most 0.32 % (the rest:
#: psignifit's trapezoid weights halve its grid's end points, λ = 0 among them; ours weigh
#: every point alike). 1 %: under the half-step bound of 1.2–1.9 %, three times the largest
#: difference seen.
TOL_CI = 1e-2


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("data", sorted(DATA))
def test_the_credible_interval_is_psignifits_under_the_same_priors(data):
    """Our median and 95 % credible interval of the threshold at 75 %, with the lapse rate
    free in [0, 0.06] as reports fit it, against the same quantiles of psignifit's own
    posterior grid under the same priors (:func:`_their_threshold_posterior`, the call in
    its docstring). Tolerance TOL_CI of each: see there."""
    x, k = DATA[data]()
    lo, med, hi = _their_threshold_posterior(x, k)
    ours = psychometric_fit(x, k, lapse_max=0.06, criterion=0.75, gof_samples=0)
    assert ours["interval"] == "posterior" and ours["ci_note"] == ""
    assert ours["threshold"] == pytest.approx(med, rel=TOL_CI)
    assert ours["ci_low"] == pytest.approx(lo, rel=TOL_CI)
    assert ours["ci_high"] == pytest.approx(hi, rel=TOL_CI)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_with_psignifits_own_width_prior_the_posterior_is_psignifits():
    """``width_prior="psignifit"`` is psignifit's default width prior, flat in w: the same
    comparison with psignifit's priors all its own (no custom prior in the call)."""
    x, k = DATA["blocks"]()
    lo, med, hi = _their_threshold_posterior(x, k, width_prior="psignifit")
    ours = psychometric_fit(x, k, gof_samples=0, width_prior="psignifit")
    assert [ours["ci_low"], ours["threshold"], ours["ci_high"]] == pytest.approx(
        [lo, med, hi], rel=TOL_CI)
    # and it is not the default's: the two priors give thresholds apart by more than that
    ln_w = psychometric_fit(x, k, gof_samples=0)
    assert abs(ln_w["threshold"] / ours["threshold"] - 1) > 2 * TOL_CI


def test_the_lapse_prior_is_psignifits():
    from psignifit._priors import lambda_prior

    v = np.linspace(0.001, 0.06, 7)
    from scipy import stats
    assert stats.beta.pdf(v, *LAPSE_PRIOR) == pytest.approx(lambda_prior(v), rel=1e-12)


def test_the_interval_holds_the_threshold_and_narrows_with_trials():
    x, k = DATA["blocks"]()
    one = psychometric_fit(x, k, gof_samples=0)
    four = psychometric_fit(np.tile(x, 4), np.tile(k, 4), gof_samples=0)
    assert one["ci_low"] < one["threshold"] < one["ci_high"] and one["ci_note"] == ""
    # the same proportions: the same maximum-likelihood threshold, and the posterior's
    # median, pulled by the prior, nearer to it with four times the answers
    assert four["threshold_ml"] == pytest.approx(one["threshold_ml"], rel=1e-3)
    ml = one["threshold_ml"]
    assert abs(four["threshold"] - ml) < 0.5 * abs(one["threshold"] - ml)
    assert four["ci_high"] - four["ci_low"] < 0.6 * (one["ci_high"] - one["ci_low"])
    # a lower level: a central interval of the same posterior, strictly inside
    wide = psychometric_fit(x, k, gof_samples=0, alpha=0.2)
    assert wide["ci_level"] == pytest.approx(0.8) and wide["threshold"] == one["threshold"]
    assert one["ci_low"] < wide["ci_low"] < wide["threshold"] < wide["ci_high"] < one["ci_high"]
    # the profile interval, kept for comparison, beside the maximum-likelihood threshold
    pr = psychometric_fit(x, k, gof_samples=0, interval="profile")
    assert pr["interval"] == "profile" and pr["threshold"] == one["threshold_ml"]
    assert pr["ci_low"] < pr["threshold"] < pr["ci_high"] and pr["p_never"] is None


N5 = np.array([0.02, 0.05, 0.1, 0.2, 0.4]), np.full(5, 20)


@pytest.mark.parametrize("criterion", [0.6, 0.75, 0.9])
@pytest.mark.parametrize("k, side, why", [
    (np.full(5, 20), "lower", "below the lowest intensity tested"),  # all right
    (np.zeros(5), "upper", "above the highest intensity tested"),  # all wrong
    (np.full(5, 10), "upper", "above the highest intensity tested"),  # at chance
])
def test_a_threshold_the_answers_do_not_bound_is_said_not_numbered(k, side, why, criterion):
    x, n = N5
    r = threshold_posterior(x, k, n, criterion=criterion)
    assert r["median"] is None and r[{"lower": "low", "upper": "high"}[side]] is None
    assert why in r["note"] and f"the {side} end is not bounded" in r["note"]


# Many answers at five levels, shaped as a shallow function whose m is where m's prior ends
# (half the span beyond the levels): at 90 % its threshold lies inside the levels (the
# lowest level is right 84 % of the time), at 60 % (the highest 66 %) too. The answers rule
# out a threshold at the criterion half a span beyond the levels on that side, yet fit the
# shallow function: a rule that tests m there, not the threshold, withdraws the end.
BOUNDED = {0.9: ("lower", np.array([168, 187, 194, 198, 199]), 200),
           0.6: ("upper", np.array([217, 226, 234, 246, 264]), 400)}


@pytest.mark.parametrize("criterion", sorted(BOUNDED))
def test_an_end_the_answers_bound_is_stated_at_any_criterion(criterion):
    side, k, n = BOUNDED[criterion]
    x = N5[0]
    r = threshold_posterior(x, k, np.full(5, n), criterion=criterion)
    assert "not bounded" not in r["note"], r["note"]
    assert r["low"] is not None and r["high"] is not None
    assert r["low"] < r["median"] < r["high"]
    # the profile likelihood, another route, agrees that the answers bound that side
    trials = np.repeat(x, n)
    right = np.concatenate([np.r_[np.ones(c), np.zeros(n - c)] for c in k])
    pr = psychometric_fit(trials, right, criterion=criterion, gof_samples=0,
                          interval="profile")
    assert pr[{"lower": "ci_low", "upper": "ci_high"}[side]] is not None, pr["ci_note"]


@pytest.mark.parametrize("args, why", [
    (([-0.1, 0.2, 0.3], [1, 2, 3], [5, 5, 5]), "above 0 only"),  # a Weibull at x ≤ 0
    (([0.1, 0.2], [6, 2], [5, 5]), "k must lie in 0..n"),  # k > n
    (([0.1, 0.2], [0, 2], [0, 5]), "k must lie in 0..n"),  # no trials
    (([0.1, 0.2, np.nan], [1, 2, 3], [5, 5, 5]), "k must lie in 0..n"),
    (([0.1, 0.2, 0.3], [1, 2], [5, 5]), "in arrays of one shape"),
])
def test_the_posterior_refuses_what_the_fit_refuses(args, why):
    for f in (threshold_posterior, fit_psychometric):
        with pytest.raises(ValueError, match=why):
            f(*args)


def test_the_posteriors_own_arguments_are_checked():
    x, n = N5
    k = np.array([10, 12, 15, 19, 20])
    with pytest.raises(ValueError, match="must lie in"):
        threshold_posterior(x, k, n, criterion=1.2)
    with pytest.raises(ValueError, match="must lie in"):
        threshold_posterior(x, k, n, alpha=0.0)
    with pytest.raises(ValueError, match="width_prior must be one of"):
        threshold_posterior(x, k, n, width_prior="jeffreys")
    with pytest.raises(ValueError, match="leave no range"):
        threshold_posterior(x, k, n, lapse_max=0.6)


def test_the_edges_of_the_lapse_and_the_criterion():
    x, n = N5
    # lapses at the bound: the interval is still stated where the answers bound it
    r = threshold_posterior(x, np.array([10, 12, 15, 17, 17]), n, lapse_max=0.06)
    assert r["low"] < r["median"] < r["high"] and r["note"] == "" and r["never"] == 0.0
    # a criterion the function may never reach: the upper end is said, not numbered
    r = threshold_posterior(x, np.array([10, 12, 15, 19, 20]), n, criterion=0.97)
    assert r["high"] is None and "may never reach the criterion" in r["note"]
    assert 0.05 < r["never"] < 0.5 and r["low"] < r["median"]
    # a criterion at the guess rate: no threshold anywhere
    r = threshold_posterior(x, np.array([10, 12, 15, 19, 20]), n, criterion=0.5)
    assert (r["median"], r["low"], r["high"]) == (None, None, None)
    assert "at or below the guess rate" in r["note"]
    with pytest.raises(ValueError, match="two intensities at least"):  # one intensity only
        threshold_posterior([0.1, 0.1 + 1e-15], [3, 4], [5, 5])


def test_equal_intensities_reached_by_different_sums_are_one_level():
    lv = levels([0.1, 0.3 - 0.2, 0.2], [1, 0, 1])
    assert lv["n"].tolist() == [2, 1] and lv["k"].tolist() == [1, 1]


def test_deviance_is_zero_for_a_saturated_fit_and_the_bootstrap_is_seeded():
    assert deviance([3, 5], [10, 10], [0.3, 0.5]) == pytest.approx(0.0, abs=1e-12)
    assert deviance([0, 10], [10, 10], [0.5, 0.5]) == pytest.approx(2 * 10 * math.log(2) * 2)
    x, k = DATA["blocks"]()
    a = psychometric_fit(x, k, gof_samples=9, seed=4)
    b = psychometric_fit(x, k, gof_samples=9, seed=4)
    assert a["gof_p"] == b["gof_p"] and 0 < a["gof_p"] <= 1 and a["seed"] == 4


def test_what_cannot_be_fitted_is_said():
    with pytest.raises(ValueError, match="two intensities at least"):
        psychometric_fit([0.1, 0.1], [1, 0], gof_samples=0)
    with pytest.raises(ValueError, match="above 0 only"):
        psychometric_fit([-0.1, 0.2, 0.3], [0, 1, 1], gof_samples=0)
    with pytest.raises(ValueError, match="function must be one of"):
        psychometric_fit([0.1, 0.2], [0, 1], function="gompertz", gof_samples=0)
    # a criterion the fitted function never reaches (above 1 − lapse): no threshold, said so
    x, k = DATA["lapses"]()
    for interval, why in (("posterior", "more probably never reaches"),
                          ("profile", "does not reach")):
        r = psychometric_fit(x, k, criterion=0.97, gof_samples=0, interval=interval)
        assert r["threshold"] is None and r["ci_low"] is None and r["ci_high"] is None
        assert why in r["ci_note"] and r["threshold_ml"] is None
    with pytest.raises(ValueError, match="interval must be"):
        psychometric_fit(x, k, gof_samples=0, interval="bootstrap")

