"""`hapticlab bench thresholds`' tables (review final item 6): a figure no session defines
is said ("—"), never printed as nan nor a crash, and the bias says how many sessions it
is over. Unit tier: the tables of hand-made results, no session run."""

import warnings

from benchmarks.thresholds import _errors, tables


def _row(fitted: int, sessions: int = 3, cap=None) -> dict:
    err = [0.01, -0.02, 0.03][:fitted]
    return {"procedure": "staircase", "sessions": sessions, "cap": cap,
            "trials_median": 20.0, "fitted": fitted, **_errors(err), "coverage": 1.0,
            "ends_unstated": sessions - fitted, "ml_fitted": fitted,
            **{"ml_" + k: v for k, v in _errors(err).items()
               if k in ("bias_log10", "rmse_log10")},
            "profile_coverage": 1.0, "ci_width_log10_median": None, "own_bias_log10": None,
            "own_p90_abs_log10": None, "own_bias_own_target_log10": None,
            "own_coverage": None}


def test_no_estimate_is_a_dash_not_nan_nor_a_crash():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's mean of nothing warns, then gives nan
        none = _errors([])
    assert set(none.values()) == {None}
    row = _row(0)
    shown = tables([row], [{"procedure": "staircase", "rows": [_row(0, cap=20)]}], 3)
    cells = [str(c) for _, _, rows in shown for r in rows for c in r]
    assert "nan" not in " ".join(cells).lower()
    assert cells.count("—") >= 10 and "0 of 3" in cells


def test_the_bias_says_how_many_sessions_it_is_over():
    shown = tables([_row(2)], [], 3)
    (_, head, rows), (_, head_ml, rows_ml) = shown
    main = dict(zip(head, rows[0], strict=True))
    assert main["with a median"] == "2 of 3" and main["bias"] == "-0.0050"
    assert dict(zip(head_ml, rows_ml[0], strict=True))["ML: with a threshold"] == "2 of 3"
