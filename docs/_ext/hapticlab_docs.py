"""Sphinx directives that write reference tables from the code at build time, so that they
cannot drift from it.

``{hapticlab-errors}``
    Every error class hapticlab raises on purpose (the subclasses of ``HapticlabError`` in
    the four packages), with its base and the first line of its docstring.
``{hapticlab-trace-channels}``
    The channels a tapping window records (``device.events.TRACE_CHANNELS``), with units.

And at the start of every build, the report of the sessions that ship with hapticlab
(``analysis.datasets.sessions_path()``), made by ``analysis.report.analyze`` — the code that
makes every report — into ``docs/_generated/bundled-report/``, so the figures the pages show
are that code's output, never a copy that could go stale.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import re

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

PACKAGES = ("device", "protocols", "analysis", "app")


def _import_all() -> None:
    """Import every module of the packages (an error class is known once defined); a module
    that cannot be imported here (one that needs a screen) is skipped."""
    for pkg in PACKAGES:
        root = importlib.import_module(pkg)
        for info in pkgutil.walk_packages(root.__path__, pkg + "."):
            if info.name.endswith("__main__"):
                continue
            try:
                importlib.import_module(info.name)
            except Exception:  # noqa: BLE001 - documented by what imports
                continue


def error_classes() -> list[type]:
    """The subclasses of ``HapticlabError``, depth first, in definition order."""
    from device.errors import HapticlabError

    _import_all()
    out: list[type] = []

    def walk(cls: type) -> None:
        for sub in cls.__subclasses__():
            if sub not in out and sub.__module__.split(".")[0] in PACKAGES:
                out.append(sub)
                walk(sub)

    walk(HapticlabError)
    return out


class ErrorsDirective(SphinxDirective):
    has_content = False

    def run(self):
        rows = []
        for cls in error_classes():
            bases = ", ".join(f"`{b.__name__}`" for b in cls.__bases__)
            doc = " ".join((inspect.getdoc(cls) or "").split("\n\n")[0].split())
            rows.append([f"`{cls.__module__}.{cls.__qualname__}`", bases, _md(doc)])
        return _table(self, ["error", "is a", "raised when"], rows)


def _md(rst: str) -> str:
    """A docstring's first paragraph as Markdown in a table cell: roles in MyST's syntax,
    literals in single backticks, no bar that would end the cell."""
    text = re.sub(r":(\w+):`~?([^`]+)`", r"{\1}`\2`", rst)
    text = text.replace("``", "`")
    return text.replace("|", "\\|")


def _table(directive: SphinxDirective, header: list[str], rows: list[list[str]]) -> list:
    """A Markdown table parsed in place (the pages are MyST Markdown)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    holder = nodes.container()
    nested_parse_with_titles(directive.state, StringList(lines, source=directive.name), holder)
    return list(holder.children)


class TraceChannelsDirective(SphinxDirective):
    has_content = False

    def run(self):
        from device.events import TRACE_CHANNELS

        return _table(self, ["channel", "unit", "what"],
                      [[f"`{name}`", f"`{unit}`", _md(what)]
                       for name, (unit, what) in TRACE_CHANNELS.items()])


def make_bundled_report(app) -> None:
    """``builder-inited``: the bundled sessions' report, figures included, into
    ``_generated/`` of the documentation's source folder (not committed)."""
    import shutil
    from pathlib import Path

    from analysis.datasets import sessions_path
    from analysis.report import analyze

    out = Path(app.srcdir) / "_generated" / "bundled-report"
    if out.exists():
        shutil.rmtree(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    analyze(sessions_path(), out, formats=("json",))


def setup(app):
    app.connect("builder-inited", make_bundled_report)
    app.add_directive("hapticlab-errors", ErrorsDirective)
    app.add_directive("hapticlab-trace-channels", TraceChannelsDirective)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
