"""Sphinx configuration for hapticlab's documentation site.

Pages are MyST Markdown, one ``#`` title each, in four sections (tutorials, how-to guides,
reference, explanation) whose indexes take every page of their folder. ``make docs`` builds
with warnings as errors and nitpicky cross-references; ``make test`` runs it.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # autodoc and sphinx-argparse import the packages from the tree

project = "hapticlab"
author = "the hapticlab authors"
copyright = "hapticlab authors, MIT licence"  # noqa: A001 (Sphinx's name)
release = "0.1.0"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinxarg.ext",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}  # .rst: numpydoc loads autosummary
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "wire-vectors.txt"]

# MyST: headings get anchors so pages can link to a section ([text](page.md#anchor)), and
# ```{directive}``` blocks plus :::{note} fences are available.
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath", "fieldlist", "substitution"]
myst_heading_anchors = 3

# Every cross-reference must resolve (nitpicky), except names from libraries whose own
# inventories we cannot fetch (the build has no network: no intersphinx).
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|pandas|pd|scipy|matplotlib|serial|psychopy|pylsl|rich)(\..*)?"),
    (r"py:.*", r"(array_like|array-like|optional|callable|default|path-like|file-like)"),
    (r"py:.*", r"(collections\.abc|typing|pathlib|os|io|argparse|enum|dataclasses)\..*"),
]

autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types and units
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

html_theme = "furo"
html_title = "hapticlab"
html_static_path: list[str] = []
