"""``hapticlab bench thresholds``: do the adaptive procedures find the simulated observer's
known JND, and how many trials do they need?

Each simulated session runs one track of the built-in protocols — wood's frequency, the
``frequency`` phase of ``thresholds`` (3-down/1-up staircase) and of ``thresholds_quest``
(QUEST+) — through the session engine, answered by a freshly drawn simulated observer
(:mod:`app.observer`: its own JND and lapse, its psychometric function known). The answers
are the observer's from the parameter values each trial renders, as in a simulated session
on the simulated device; the device's windows are not run (the observer's answers do not
depend on them, and a session of taps costs seconds a trial). Each session's answers are
fitted as ``hapticlab analyze`` fits them (a Weibull, guess 1/2, lapse ≤ 0.06, the
threshold at 75 %: the posterior median with its 95 % credible interval) and compared with
the observer's true threshold at 75 %:

* ``bias``: mean of log10(estimate / truth), and as a share of the true threshold (the JND
  in the procedure's units); ``rmse``: its root mean square, which a few wild fits swell;
  ``median`` and ``p90``: the median and 90th percentile of |log10(estimate / truth)|, and
  the share of fits off by more than 0.2 log10 (a factor 1.6);
* ``coverage``: the share of sessions whose 95 % credible interval holds the truth
  (nominal 95 %; a binomial SE of about 1.5 points at 200 sessions); an end not stated (the
  answers do not bound it) is open on that side;
* beside them, the maximum-likelihood threshold's bias and the coverage of its 95 %
  profile-likelihood interval (``interval="profile"``), which the report stated before;
* the procedure's own estimate beside the fit: the staircase's reversal average (which
  estimates the 79.4 % point it converges on, not 75 %: its bias against the 75 % truth is
  shown, and against its own 79.4 % truth), QUEST+'s posterior mean and the coverage of
  its 95 % credible interval;
* trials for a precision: sessions capped at 20–120 trials, the errors and the median
  interval width at each cap, and the fewest trials at which 90 % of the estimates lie
  within 0.1 log10 (±26 %) and 0.05 log10 (±12 %) of the truth.

Every session's observer and answers come from ``SeedSequence([seed, k])`` (``--seeds``:
the study seed, default 1); ``--sessions`` sessions per procedure (default 200; the cap
sweep runs a third as many per cap, three at least).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ._common import emit, parse_seeds, print_table

__all__ = ["simulate_track", "coverage", "precision", "tables", "main", "PROCEDURES"]

#: procedure → the built-in protocol whose ``frequency`` phase it runs (track wood-up)
PROCEDURES = {"staircase": "thresholds", "questplus": "thresholds_quest"}
PHASE, TRACK, CRITERION = "frequency", "wood-up", 0.75
CAPS = (20, 30, 40, 60, 80, 120)
PRECISIONS = (0.1, 0.05)


def _protocol(procedure: str, cap: int | None = None):
    """The protocol reduced to the one track, and with ``cap`` trials at most (a staircase
    then runs until the cap, a QUEST+ track for ``cap`` answers)."""
    from protocols import load_protocol
    from protocols.adaptive import Staircase

    p = load_protocol(PROCEDURES[procedure])
    phase = next(ph for ph in p.phases if ph.name == PHASE)
    a = phase.adaptive
    a = dataclasses.replace(a, tracks=tuple(t for t in a.tracks if t.name == TRACK), catch=0.0)
    if cap is not None:
        proc = dataclasses.replace(a.procedure, stop_reversals=10_000) \
            if isinstance(a.procedure, Staircase) else \
            dataclasses.replace(a.procedure, trials=cap)
        a = dataclasses.replace(a, procedure=proc, max_trials=cap)
    return dataclasses.replace(p, phases=(dataclasses.replace(phase, adaptive=a),))


def simulate_track(protocol, observer, seed: int) -> dict:
    """One session of ``protocol``'s one adaptive track answered by ``observer``: the
    intensities and answers, and the procedure's own estimate at the end."""
    from protocols import Attempt, SessionEngine

    engine = SessionEngine(protocol, seed, "bench")
    phase = protocol.phases[0]
    parameter = phase.adaptive.parameter
    log, xs, right = [], [], []
    while hasattr(t := engine.next_trial(log), "item"):
        rng = np.random.default_rng(np.random.SeedSequence([seed, t.trial_index]))
        values = [getattr(t.sample_of(protocol, s).scene.transient, parameter)
                  for s in t.samples]
        ok = observer.judge(parameter, values, rng) == t.stimulus.larger
        log.append(Attempt(t.item, "valid", correct=ok))
        xs.append(t.stimulus.intensity)
        right.append(int(ok))
    proc = phase.adaptive.procedure
    state = engine.procedure_state(phase.name, TRACK, tuple(bool(r) for r in right))
    return {"x": xs, "correct": right, "estimate": proc.estimate(state),
            "target": getattr(proc, "target", CRITERION)}


def _observer(seed: int, k: int):
    from app.observer import draw_observer

    return draw_observer(np.random.default_rng(np.random.SeedSequence([seed, k, 1])))


def _fit(run: dict, interval: str = "posterior", width_prior: str = "ln-w") -> dict:
    from analysis.psychometric import psychometric_fit

    return psychometric_fit(run["x"], run["correct"], function="weibull", criterion=CRITERION,
                            lapse_max=0.06, gof_samples=0, interval=interval,
                            width_prior=width_prior)


def _covers(fit: dict, truth: float) -> bool:
    """Whether ``fit``'s interval holds ``truth``; an end not stated is open on its side."""
    lo, hi = fit["ci_low"], fit["ci_high"]
    return (lo is None or lo <= truth) and (hi is None or truth <= hi)


def coverage(procedure: str, sessions: int, seed: int = 1, cap: int | None = None,
             width_prior: str = "ln-w") -> dict:
    """Bias, RMS error and interval coverage of ``sessions`` simulated sessions;
    ``width_prior="psignifit"`` fits with psignifit 4's width prior, flat in w, instead of
    the report's (:func:`analysis.psychometric.threshold_posterior`), to show why the report
    departs from it."""
    protocol = _protocol(procedure, cap)
    err, covered, own_err, own_target_err, own_cov, widths, trials = [], [], [], [], [], [], []
    ml_err, prof_covered, unstated = [], [], 0
    t0 = time.perf_counter()
    for k in range(sessions):
        obs = _observer(seed, k)
        truth = obs.threshold("frequency", CRITERION, "log")
        run = simulate_track(protocol, obs, int(np.random.SeedSequence([seed, k])
                                                .generate_state(1, np.uint64)[0] % 2**63))
        fit, prof = _fit(run, width_prior=width_prior), _fit(run, "profile")
        trials.append(len(run["x"]))
        if fit["threshold"] is not None:
            err.append(math.log10(fit["threshold"] / truth))
        if fit["threshold_ml"] is not None:
            ml_err.append(math.log10(fit["threshold_ml"] / truth))
        covered.append(_covers(fit, truth))
        prof_covered.append(_covers(prof, truth))
        lo, hi = fit["ci_low"], fit["ci_high"]
        unstated += lo is None or hi is None
        if lo is not None and hi is not None:
            widths.append(math.log10(hi / lo))
        est = run["estimate"]
        own = est.get("mean")
        if own is not None and own > 0:
            own_err.append(math.log10(own / truth))
            own_truth = obs.threshold("frequency", run["target"], "log")
            own_target_err.append(math.log10(own / own_truth))
        if "ci" in est:
            own_cov.append(est["ci"][0] <= truth <= est["ci"][1])
    ml = _errors(ml_err)
    return {"procedure": procedure, "sessions": sessions, "cap": cap,
            "trials_median": float(np.median(trials)), "fitted": len(err), **_errors(err),
            "coverage": float(np.mean(covered)), "ends_unstated": unstated,
            "ml_fitted": len(ml_err), "ml_bias_log10": ml["bias_log10"],
            "ml_rmse_log10": ml["rmse_log10"],
            "profile_coverage": float(np.mean(prof_covered)),
            "ci_width_log10_median": float(np.median(widths)) if widths else None,
            "own_bias_log10": float(np.mean(own_err)) if own_err else None,
            "own_p90_abs_log10": float(np.quantile(np.abs(own_err), 0.9)) if own_err else None,
            "own_bias_own_target_log10": float(np.mean(own_target_err))
            if own_target_err else None,
            "own_coverage": float(np.mean(own_cov)) if own_cov else None,
            "seconds": time.perf_counter() - t0}


def _errors(err) -> dict:
    """Bias, RMS and the spread of ``err`` (log10 of estimate/truth over the sessions that
    gave an estimate); each None when no session did: undefined, not NaN."""
    if not len(err):
        return dict.fromkeys(("bias_log10", "bias_share", "rmse_log10", "median_abs_log10",
                              "p90_abs_log10", "off_by_0_2"))
    e = np.asarray(err, dtype=float)
    off = np.abs(e)
    return {"bias_log10": float(e.mean()), "bias_share": float(10 ** e.mean() - 1),
            "rmse_log10": float(np.sqrt(np.mean(e ** 2))),
            "median_abs_log10": float(np.median(off)),
            "p90_abs_log10": float(np.quantile(off, 0.9)),
            "off_by_0_2": float(np.mean(off > 0.2))}


def precision(procedure: str, sessions: int, seed: int = 1, caps=CAPS) -> dict:
    """Errors and interval width at each cap on trials, and the fewest trials at which 90 %
    of the estimates lie within each precision of :data:`PRECISIONS` [log10]."""
    rows = [coverage(procedure, sessions, seed + 1000 + c, cap=c) for c in caps]
    need = {p: next((r["cap"] for r in rows if r["p90_abs_log10"] is not None
                     and r["p90_abs_log10"] <= p), None)
            for p in PRECISIONS}
    return {"procedure": procedure, "rows": rows, "trials_for": need}


def tables(cov: list[dict], prec: list[dict], n: int) -> list[tuple[str, list, list]]:
    """The printed tables (title, header, rows) of :func:`coverage`'s and :func:`precision`'s
    results. An undefined figure (no session gave an estimate, no interval had both ends)
    is "—"; the bias and errors are over the sessions that gave an estimate, and how many
    those are is printed beside them ("of n")."""
    def of(r, key="fitted"):
        return f"{r[key]} of {r['sessions']}"

    out = [(f"the observer's true 75 % threshold against each procedure ({n} sessions; "
            "bias and RMS in log10 of estimate/truth, over the sessions with a stated "
            "median; the posterior median and its 95 % credible interval, nominal coverage "
            "95 %, over all sessions)",
            ["procedure", "trials (median)", "with a median", "bias", "bias (% of JND)",
             "RMS", "median |err|", "90 % |err|", "> 0.2", "coverage", "ends unstated",
             "CI width (median)"],
            [(r["procedure"], f"{r['trials_median']:.0f}", of(r), _f(r["bias_log10"], "+.4f"),
              _f(r["bias_share"], "+.1%"), _f(r["rmse_log10"], ".4f"),
              _f(r["median_abs_log10"], ".4f"), _f(r["p90_abs_log10"], ".4f"),
              _f(r["off_by_0_2"], ".1%"), _f(r["coverage"], ".1%"),
              r["ends_unstated"], _f(r["ci_width_log10_median"], ".3f")) for r in cov]),
           ("beside it: the maximum-likelihood threshold and its 95 % profile interval, "
            "and the procedure's own estimate (log10 of estimate/truth)",
            ["procedure", "ML: with a threshold", "ML: bias", "ML: RMS", "profile coverage",
             "own estimate: bias", "vs its own target", "its 90 % |err|", "own coverage"],
            [(r["procedure"], of(r, "ml_fitted"), _f(r["ml_bias_log10"], "+.4f"),
              _f(r["ml_rmse_log10"], ".4f"), _f(r["profile_coverage"], ".1%"),
              _f(r["own_bias_log10"], "+.4f"), _f(r["own_bias_own_target_log10"], "+.4f"),
              _f(r["own_p90_abs_log10"], ".4f"), _f(r["own_coverage"], ".1%"))
             for r in cov])]
    for p in prec:
        out.append((f"{p['procedure']}: trials against precision ({p['rows'][0]['sessions']} "
                     "sessions a cap)",
                     ["trials at most", "trials (median)", "with a median", "bias",
                      "median |err|", "90 % |err|", "RMS", "coverage", "profile coverage",
                      "CI width (median)"],
                     [(r["cap"], f"{r['trials_median']:.0f}", of(r),
                       _f(r["bias_log10"], "+.4f"), _f(r["median_abs_log10"], ".4f"),
                       _f(r["p90_abs_log10"], ".4f"), _f(r["rmse_log10"], ".4f"),
                       _f(r["coverage"], ".1%"), _f(r["profile_coverage"], ".1%"),
                       _f(r["ci_width_log10_median"], ".3f")) for r in p["rows"]]))
    return out


def main(args) -> int:
    seed = parse_seeds(getattr(args, "seeds", None), [1])[0]
    n = int(getattr(args, "sessions", 200))
    cov = [coverage(p, n, seed) for p in PROCEDURES]
    prec = [precision(p, max(3, n // 3), seed) for p in PROCEDURES]
    if args.json:
        emit({"seed": seed, "sessions": n, "coverage": cov, "precision": prec}, True)
        return 0
    shown = tables(cov, prec, n)
    for (title, header, rows) in shown[:2]:
        print_table(title, header, rows)
    for p, (title, header, rows) in zip(prec, shown[2:], strict=True):
        print_table(title, header, rows)
        print("  fewest trials with 90 % of the estimates within " + "; ".join(
            f"{q:g} log10 (±{100 * (10 ** q - 1):.0f} %): {v if v else 'more than tested'}"
            for q, v in p["trials_for"].items()))
    return 0


def _f(v, spec: str) -> str:
    """``v`` formatted, or "—" where it is undefined (None)."""
    return "—" if v is None else format(v, spec)
