"""What an analysis type is (:class:`AnalysisType`), and the check that none of its results
vanishes on the way to report.json."""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

__all__ = ["AnalysisType", "ResultNotReported", "report_entry"]


@dataclass(frozen=True)
class AnalysisType:
    """One analysis type: which phase designs it analyses, and everything the report says
    of it. Each function takes what the report has at that point:

    Attributes
    ----------
    name : str
        The ``type`` in report.json (``oneway``, ``factorial``, ``identification``).
    matches : callable (phase design dict) -> bool
        Whether a recorded phase design calls for this analysis (types are asked in the
        order they were registered).
    analyse : callable (rows DataFrame, phase design dict, alpha) -> result
        The analysis itself (:mod:`analysis.study`), raising
        :class:`~analysis.stats.StatsError` when it cannot be computed.
    entry : callable (result) -> dict
        Its part of report.json. Every key of the result must be read here or by
        ``methods``, or be named in ``internal``: a key left out by mistake stops the
        report (:class:`ResultNotReported`) instead of vanishing.
    methods : callable (result, phase design dict, recorded design dict) -> str
        Its methods paragraph, written from what was computed (after the title).
    summary : callable (report entry dict) -> str
        Its findings in words, APA style (after the bold title and the count of people).
    markdown : callable (report entry dict) -> (list of str, list of str)
        Its section's Markdown and its appendix tables.
    figures : callable (analysis dict, data DataFrame, folder Path) -> list of str
        Writes its figures; returns their file names.
    captions : mapping
        Caption of a figure by the end of its file name.
    internal : tuple of str
        Result keys (dotted paths, ``*`` for any key) that do not go to report.json, each
        for a reason its module states (used by figures only, or said in other words).
    """

    name: str
    matches: Callable[[dict], bool]
    analyse: Callable[[pd.DataFrame, dict, float], Any]
    entry: Callable[[Any], dict]
    methods: Callable[[Any, dict, dict], str]
    summary: Callable[[dict], str]
    markdown: Callable[[dict], tuple[list[str], list[str]]]
    figures: Callable[[dict, pd.DataFrame, Path], list[str]]
    captions: Mapping[str, str] = field(default_factory=dict)
    internal: tuple[str, ...] = ()


class ResultNotReported(RuntimeError):
    """An analysis computed a value that its report entry neither writes nor declares
    internal (a programming error, named so it is fixed rather than lost)."""


class _Reads(dict):
    """A result dict that notes which keys were read (nested dicts too, by dotted path)."""

    def __init__(self, d: Mapping, path: str, log: dict):
        super().__init__(d)
        self._path, self._log = path, log
        log.setdefault(path, (set(d), set()))

    def _wrap(self, k, v):
        if isinstance(v, dict) and not isinstance(v, _Reads):
            return _Reads(v, f"{self._path}.{k}" if self._path else str(k), self._log)
        return v

    def _read(self, k) -> None:
        self._log[self._path][1].add(k)

    def __getitem__(self, k):
        self._read(k)
        return self._wrap(k, super().__getitem__(k))

    def get(self, k, default=None):
        self._read(k)
        return self._wrap(k, super().get(k, default))

    def items(self):
        return [(k, self[k]) for k in self.keys()]

    def values(self):
        return [self[k] for k in self.keys()]

    def read_all(self) -> None:
        """Everything below is reported (the dict itself went into the entry)."""
        for v in self.values():
            if isinstance(v, _Reads):
                v.read_all()


def _reached(v) -> None:
    """Mark every tracked dict found in an entry's output as read whole."""
    if isinstance(v, _Reads):
        v.read_all()
    elif isinstance(v, dict):
        for x in v.values():
            _reached(x)
    elif isinstance(v, list | tuple):
        for x in v:
            _reached(x)


def report_entry(kind: AnalysisType, result, phase: dict, design: dict) -> tuple[dict, str]:
    """``kind``'s report.json entry and methods paragraph for ``result``.

    Raises
    ------
    ResultNotReported
        Naming each key of the result (dotted path) that reached neither.
    """
    if not isinstance(result, dict):
        return kind.entry(result), kind.methods(result, phase, design)
    log: dict = {}
    tracked = _Reads(result, "", log)
    entry = kind.entry(tracked)
    _reached(entry)
    methods = kind.methods(tracked, phase, design)
    lost = sorted(f"{path}.{k}" if path else str(k) for path, (keys, read) in log.items()
                  for k in keys - read)
    lost = [p for p in lost if not any(fnmatch.fnmatchcase(p, pat) for pat in kind.internal)]
    if lost:
        raise ResultNotReported(f"analysis type {kind.name!r}: {', '.join(lost)} of its "
                                "result reach neither report.json nor its methods; write "
                                "them in its entry, or name them in its internal keys")
    return _plain(entry), methods


def _plain(v):
    """The entry with tracked dicts made plain dicts again."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in dict.items(v)}
    if isinstance(v, list):
        return [_plain(x) for x in v]
    return v
