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

# Every cross-reference must resolve (nitpicky): a page, a heading, a function or a class
# that does not exist fails the build. Not checked, where it is not feasible: names from
# other libraries and the standard library (the build has no network for their
# inventories), private names, and module constants and attributes, which docstrings cite
# by their bare name from the module that defines them (the API pages document each
# module's public functions and classes, its __all__).
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|pandas|pd|scipy|matplotlib|serial|psychopy|pylsl|rich|numba)(\..*)?"),
    (r"py:.*", r"(array_like|array-like|optional|callable|default|path-like|file-like)"),
    (r"py:.*", r"(collections\.abc|typing|pathlib|os|io|argparse|enum|dataclasses|time|"
               r"threading|subprocess|signal|json|ctypes)\..*"),
    (r"py:(data|attr|const)", r".*"),
    (r"py:(mod|meth|class|func)", r"\w+"),  # a bare name, relative to where it is cited
    # modules inside the packages that the API pages do not document (their docstrings are
    # for the code's readers)
    (r"py:.*", r"(device\.(sim|matching|serial|fileio)|app\.matching_cli|analysis\.study)"
               r"(\..*)?"),
    (r"py:.*", r"(.*\.)?_\w*"),
]


def _reexports() -> list[tuple[str, str]]:
    """The packages' public names (``device.DeviceInfo``): docstrings cite them so, and the
    API pages document each under the module that defines it. Only names that exist are
    let through, so a renamed one still fails the build."""
    import importlib

    out = []
    for pkg in ("device", "protocols", "analysis"):
        for name in importlib.import_module(pkg).__all__:
            out.append((r"py:.*", rf"{pkg}\.{name}(\.\w+)?"))
    return out


nitpick_ignore_regex += _reexports()

autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types and units
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

html_theme = "furo"
html_title = "hapticlab"
html_static_path: list[str] = []
