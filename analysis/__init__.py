"""From raw session files to a study's statistics, figures and report.

Reads the session folders of DESIGN.md (the format is :mod:`analysis.session_format`'s);
imports neither the device nor the protocol packages. The public API (stable names and
parameters), in the manner of pingouin — a long-format DataFrame and column names in, a
tidy DataFrame out::

    load_sessions(path)                      select_sessions(data, protocol=…, kind=…, …)
    preflight(data, dv, within, subject)     zscore_by_subject(data, dv, subject)
    pairwise_ttests(data, dv, within, subject, padjust="holm")
    rm_anova(data, dv, within, subject)
    identification_scores(data, subject, correct, repetition=None, group=None)
    friedman(data, dv, within, subject)      pairwise_wilcoxon(data, dv, within, subject)
    dz_ci(dz, n)                             participant_identification_test(data, subject, correct)

``analysis.datasets`` holds a small committed example (the docstrings' examples run on it).
"""

import importlib

#: where each public name lives: imported on first use (PEP 562), so a part of the
#: application that needs only the file format (analysis.session_format: the recorder,
#: the CLI's startup) does not load pandas and SciPy with it
_HOMES = {
    "datasets": "", "ordinal": "",
    "LoadError": "load", "load_sessions": "load", "select_sessions": "load",
    "tap_velocities": "load",
    **{name: "stats" for name in (
        "StatsError", "dz_ci", "equivalence_ttests", "friedman", "identification_scores",
        "np2_ci", "p_adjust", "pairwise_ttests", "pairwise_wilcoxon",
        "participant_identification_test", "preflight", "rm_anova", "zscore_by_subject")},
}

__all__ = ["LoadError", "StatsError", "datasets", "dz_ci", "equivalence_ttests", "ordinal",
           "friedman",
           "identification_scores",
           "load_sessions", "np2_ci", "p_adjust", "pairwise_ttests", "pairwise_wilcoxon",
           "participant_identification_test", "preflight", "rm_anova", "select_sessions",
           "tap_velocities", "zscore_by_subject"]


def __getattr__(name: str):
    if name not in _HOMES:
        raise AttributeError(f"module 'analysis' has no attribute {name!r}")
    home = _HOMES[name]
    value = (importlib.import_module(f".{name}", __name__) if not home
             else getattr(importlib.import_module(f".{home}", __name__), name))
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
