"""Statistics in the manner of pingouin: long-format DataFrame and column names in, tidy table out.

Every function works on per-subject cell means (repeated ratings of a cell are averaged
first), refuses to compute on data it cannot analyse honestly (see :func:`preflight`), and
returns tables without NaN or infinity. Split by family, as pingouin is:

- :mod:`.shaping`: cell means (long and wide), the preflight, z-scores per subject;
- :mod:`.parametric`: repeated-measures ANOVA, paired t-tests, equivalence tests;
- :mod:`.nonparametric`: Friedman and Wilcoxon signed-rank tests;
- :mod:`.multicomp`: p adjustment; :mod:`.effsize`: effect-size confidence intervals;
- :mod:`.proportions`: identification scores and paired comparisons against chance;
- :mod:`.mixed`: the linear mixed model of trial-level ratings;
- :mod:`._base`: the error, the tolerance and the checks they share.
"""

from __future__ import annotations

from ._base import StatsError, tie_groups
from .effsize import dz_ci, np2_ci
from .mixed import mixed_oneway
from .multicomp import p_adjust
from .nonparametric import friedman, pairwise_wilcoxon, signed_rank_test
from .parametric import equivalence_ttests, pairwise_ttests, rm_anova
from .proportions import (
    identification_scores,
    order_bias,
    pair_preferences,
    participant_identification_test,
)
from .shaping import cell_means, preflight, wide_means, zscore_by_subject

__all__ = ["preflight", "zscore_by_subject", "pairwise_ttests", "rm_anova",
           "identification_scores", "cell_means", "wide_means", "p_adjust", "StatsError",
           "friedman", "pairwise_wilcoxon", "dz_ci", "participant_identification_test",
           "mixed_oneway", "np2_ci", "signed_rank_test", "tie_groups", "equivalence_ttests",
           "pair_preferences", "order_bias"]
