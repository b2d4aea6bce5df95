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
sys.path.insert(0, str(Path(__file__).parent / "_ext"))  # our directives: tables from the code

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
    "hapticlab_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}  # .rst: numpydoc loads autosummary
root_doc = "index"
exclude_patterns = ["_build", "_ext", "_generated", "Thumbs.db", ".DS_Store", "wire-vectors.txt"]

# MyST: headings get anchors so pages can link to a section ([text](page.md#anchor)), and
# ```{directive}``` blocks plus :::{note} fences are available.
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath", "fieldlist", "substitution"]
myst_heading_anchors = 3

# Every cross-reference must resolve (nitpicky): a page, a heading, a function or a class
# that does not exist fails the build. Where that is not feasible: names from other
# libraries and the standard library are not checked (the build has no network for their
# inventories), nor module constants and attributes, which docstrings cite by their bare
# name, nor bare relative names. A docstring's reference to one of our own objects that the
# API pages do not document passes when the object exists (_ours_exists below), so a renamed
# or removed function still fails the build.
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|pandas|pd|scipy|matplotlib|serial|psychopy|pylsl|rich|numba)(\..*)?"),
    (r"py:.*", r"(array_like|array-like|optional|callable|default|path-like|file-like)"),
    (r"py:.*", r"(collections\.abc|typing|pathlib|os|io|argparse|enum|dataclasses|time|"
               r"threading|subprocess|signal|json|ctypes)\..*"),
    (r"py:(data|attr|const)", r".*"),
    (r"py:(mod|meth|class|func)", r"\w+"),  # a bare name, relative to where it is cited
]

_OURS = ("app", "device", "protocols", "analysis", "benchmarks")


def _ours_exists(app, domain, node) -> bool | None:
    """``warn-missing-reference``: quiet for a reference to an object of ours that exists
    but has no entry on the API pages (an internal module's function, a package's
    re-export); the warning stands when the object does not exist."""
    target = node.get("reftarget", "")
    if domain is None or domain.name != "py":
        return None
    module = node.get("py:module") or ""
    for name in (target, f"{module}.{target}"):  # as written, or relative to its module
        if name.split(".")[0] in _OURS and _exists(name):
            return True
    return None


def _exists(dotted: str) -> bool:
    import importlib

    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


def setup(app):
    app.connect("warn-missing-reference", _ours_exists)


autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types and units
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

html_theme = "furo"
html_title = "hapticlab"
html_static_path: list[str] = []
