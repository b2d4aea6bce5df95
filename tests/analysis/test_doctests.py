"""The analysis API's docstring examples run, on the committed example dataset."""

import doctest
import importlib

import pytest

MODULES = ("analysis.stats", "analysis.load", "analysis.datasets", "analysis.study",
           "analysis.bids",
           "analysis.session_format")


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE
                             | doctest.ELLIPSIS)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed"
    if name in ("analysis.stats", "analysis.load", "analysis.datasets"):
        assert result.attempted > 0
