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

from . import datasets, ordinal
from .load import LoadError, load_sessions, select_sessions, tap_velocities
from .stats import (
    StatsError,
    dz_ci,
    equivalence_ttests,
    friedman,
    identification_scores,
    np2_ci,
    p_adjust,
    pairwise_ttests,
    pairwise_wilcoxon,
    participant_identification_test,
    preflight,
    rm_anova,
    zscore_by_subject,
)

__all__ = ["LoadError", "StatsError", "datasets", "dz_ci", "equivalence_ttests", "ordinal",
           "friedman",
           "identification_scores",
           "load_sessions", "np2_ci", "p_adjust", "pairwise_ttests", "pairwise_wilcoxon",
           "participant_identification_test", "preflight", "rm_anova", "select_sessions",
           "tap_velocities", "zscore_by_subject"]
