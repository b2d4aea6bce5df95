"""The analysis API's docstring examples run, on the committed example dataset."""

import doctest
import importlib

import pytest

#: the statistics by family (analysis/stats/), then the rest of the API
STATS = ("analysis.stats.shaping", "analysis.stats.parametric", "analysis.stats.nonparametric",
         "analysis.stats.multicomp", "analysis.stats.effsize", "analysis.stats.proportions",
         "analysis.stats.mixed", "analysis.stats._base")
MODULES = (*STATS, "analysis.load", "analysis.datasets", "analysis.study", "analysis.bids",
           "analysis.session_format")


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE
                             | doctest.ELLIPSIS)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed"
    if name in (*STATS, "analysis.load", "analysis.datasets") and name != "analysis.stats.mixed":
        assert result.attempted > 0  # every family shows its use (mixed.py has no example)
