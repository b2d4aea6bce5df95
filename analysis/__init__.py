"""From raw session files to a study's statistics, figures and report.

Reads the session folders of DESIGN.md; imports neither the device nor the protocol
packages. The public API (stable names and parameters)::

    load_sessions(path)
    preflight(data, dv, within, subject)
    zscore_by_subject(data, dv, subject)
    pairwise_ttests(data, dv, within, subject, padjust="holm")
    rm_anova(data, dv, within, subject)
    identification_scores(data, subject, correct, repetition=None, group=None)
"""

from .load import LoadError, load_sessions, tap_velocities
from .stats import (
    StatsError,
    identification_scores,
    p_adjust,
    pairwise_ttests,
    preflight,
    rm_anova,
    zscore_by_subject,
)

__all__ = ["LoadError", "StatsError", "identification_scores", "load_sessions", "p_adjust",
           "pairwise_ttests", "preflight", "rm_anova", "tap_velocities", "zscore_by_subject"]
