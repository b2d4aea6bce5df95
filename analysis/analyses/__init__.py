"""Each analysis type in one module, found by the phase design it analyses.

In the manner of pingouin, which splits its statistics by family, each type
(:class:`~analysis.analyses.base.AnalysisType`) owns its analysis, its report.json entry,
its methods paragraph, its findings in words, its Markdown section and its figures;
:mod:`analysis.report` keeps the page around them. A phase design is analysed by the first
registered type that :attr:`~analysis.analyses.base.AnalysisType.matches` it:

- ``identification`` (:mod:`.identification`): ``dv = "answer"``;
- ``oneway`` (:mod:`.oneway`): ratings, ``within = ["sample"]``;
- ``factorial`` (:mod:`.factorial`): ratings over two or three factors;
- ``comparison`` (:mod:`.comparison`): ``dv = "choice"``, paired comparisons;
- ``threshold`` (:mod:`.threshold`): ``dv = "forced_choice"``, adaptive phases' thresholds.

A new type is a module that builds an ``AnalysisType`` and a line in :data:`TYPES`.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..stats import StatsError
from ..study import analysed_phases, device_summary, phase_rows
from .base import AnalysisType, ResultNotReported, report_entry
from .comparison import COMPARISON
from .factorial import FACTORIAL
from .identification import IDENTIFICATION
from .oneway import ONEWAY
from .threshold import THRESHOLD

__all__ = ["AnalysisType", "ResultNotReported", "TYPES", "analysis_for", "analysis_type",
           "analyse_phase", "analyse_recorded", "report_entry", "save_figures"]

#: the analysis types, in the order a phase design is matched against them
TYPES: tuple[AnalysisType, ...] = (IDENTIFICATION, ONEWAY, FACTORIAL, COMPARISON, THRESHOLD)


def analysis_for(phase: dict) -> AnalysisType:
    """The analysis type a recorded phase design calls for.

    Raises
    ------
    StatsError
        When no type analyses such a design (naming its dv and factors).
    """
    for t in TYPES:
        if t.matches(phase):
            return t
    raise StatsError(f"no analysis type for a phase with dv {phase.get('dv')!r} and "
                     f"factors {phase.get('within')!r}")


def analysis_type(name: str) -> AnalysisType:
    """The analysis type called ``name`` (a report entry's ``type``)."""
    for t in TYPES:
        if t.name == name:
            return t
    raise KeyError(f"no analysis type {name!r}; the types are "
                   f"{', '.join(t.name for t in TYPES)}")


def analyse_phase(rows: pd.DataFrame, phase: dict, alpha: float = 0.05) -> dict:
    """The analysis a recorded phase design calls for, on that phase's rows.

    Returns
    -------
    dict
        ``type`` (the :class:`AnalysisType`'s name) and ``result`` (the analysis' dict),
        plus ``device`` (:func:`analysis.study.device_summary` of the phase).
    """
    kind = analysis_for(phase)
    return {"type": kind.name, "result": kind.analyse(rows, phase, alpha),
            "device": device_summary(rows)}


def analyse_recorded(data: pd.DataFrame, protocol: str, phase: str, alpha: float = 0.05) -> dict:
    """The analysis that ``protocol``'s recorded design declares for ``phase``, on the rows
    of ``data`` (from :func:`analysis.load_sessions`, selected or not).

    Raises
    ------
    StatsError
        When no session of that protocol recorded a design analysing that phase, or the
        sessions recorded more than one design under that name.
    """
    designs = data.attrs.get("designs", {})
    keys = sorted(set(data.loc[data["protocol"] == protocol, "design_key"]) - {""})
    if not keys:
        raise StatsError(f"no session of protocol {protocol!r} with a recorded design")
    if len(keys) > 1:
        raise StatsError(f"protocol {protocol!r} was recorded with {len(keys)} designs "
                         f"({', '.join(keys)}); analyse them apart (select by design_key)")
    match = [p for p in analysed_phases(designs[keys[0]]) if p["name"] == phase]
    if not match:
        raise StatsError(f"protocol {protocol!r} does not analyse a phase {phase!r}")
    return analyse_phase(phase_rows(data, keys[0], phase), match[0], alpha)


def save_figures(data: pd.DataFrame, analyses: list[dict], out: Path) -> list[str]:
    """Every figure of every computed analysis (PNG and SVG); returns the file names."""
    files = []
    for a in analyses:
        if not isinstance(a["result"], str):
            files += analysis_type(a["type"]).figures(a, data, out)
    return files
