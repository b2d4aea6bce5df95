"""The API's analysis commands: the report, the exports and the power of a design
(``hapticlab analyze``, ``export``, ``power``)."""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import AnalysisError, UsageError

__all__ = ["analyze", "export", "power"]


def analyze(data: str | Path, out: str | Path, *, formats=("html", "md", "json"),
            protocol: str | list[str] | None = None, kind: str | None = None,
            status: str = "complete", participants: list[str] | None = None,
            since: str | None = None, until: str | None = None,
            drop_invalid: bool = False, ids: str = "check", sim_device: bool = False,
            progress=None) -> dict:
    """Select sessions, run the analyses their designs call for, write the report.

    Parameters are those of :func:`analysis.report.analyze` (``progress``: how far it has
    got, e.g. :func:`app.api._say.progress_to_stderr`); its errors come back as
    :class:`~app.errors.AnalysisError`.

    Returns
    -------
    dict
        The report's content (report.json).
    """
    from analysis import LoadError, StatsError
    from analysis.report import analyze as _analyze

    bad = set(formats) - {"html", "md", "json"}
    if bad:
        raise UsageError(f"formats are html, md, json; got {sorted(bad)}")
    try:
        return _analyze(data, out, tuple(formats), protocol=protocol, kind=kind, status=status,
                        participants=participants, since=since, until=until,
                        drop_invalid=drop_invalid, ids=ids, sim_device=sim_device,
                        progress=progress)
    except (LoadError, StatsError) as exc:
        raise AnalysisError(str(exc)) from None
    except OSError as exc:
        from app.errors import io_error

        raise io_error(exc, "cannot write the report") from None


def export(data: str | Path, out: str | Path, fmt: str = "long-csv", **selection) -> list[Path]:
    """The analysed trials as files for JASP, SPSS or R (:func:`analysis.export.export`);
    its errors come back as :class:`~app.errors.AnalysisError`.

    Returns
    -------
    list of Path
        The files written, ``codebook.csv`` last. ``progress`` in ``selection``: how far it
        has got (as :func:`analyze`).
    """
    from analysis import LoadError, StatsError
    from analysis.export import FORMATS
    from analysis.export import export as _export

    if fmt not in FORMATS:
        raise UsageError(f"formats are {', '.join(FORMATS)}; got {fmt!r}")
    try:
        return _export(data, out, fmt, **selection)
    except (LoadError, StatsError) as exc:
        raise AnalysisError(str(exc)) from None
    except OSError as exc:
        from app.errors import io_error

        raise io_error(exc, "cannot write the export") from None


def power(protocol: str | Path, *, subjects, reps, effect: float = 1.0, alpha: float = 0.05,
          experiments: int = 10_000, sd_trial: float | None = None,
          sd_interaction: float = 0.5, sd_subject: float = 0.8,
          pilot: str | Path | None = None) -> dict:
    """Power of a paired difference and precision of a sample's mean against participants
    and repetitions, for the last analysed rating phase of ``protocol``, by Monte-Carlo
    (``hapticlab power``; :func:`analysis.power.power_table`).

    Parameters
    ----------
    protocol : str or path
        A built-in name or a protocol file.
    subjects, reps : sequence of int
        Participant counts (at least 2) and repetitions per cell (at least 1).
    effect : float
        The key contrast [scale points].
    alpha : float
        Significance level, Bonferroni-divided over every pair of the phase's samples.
    experiments : int
        Simulated experiments per cell.
    sd_trial, sd_interaction, sd_subject : float
        The SDs [scale points] of trial noise (default 0.9), participant × sample and
        participant; with ``pilot`` estimated from its ratings instead.
    pilot : path, optional
        A folder of pilot sessions of this protocol.

    Returns
    -------
    dict
        ``protocol``, ``phase``, ``comparisons``, ``sd`` (the three SDs used) and
        ``table`` (DataFrame: ``subjects``, ``reps``, ``power``, ``ci_halfwidth``).

    Raises
    ------
    UsageError
        Too few subjects or repetitions, a protocol without an analysed rating phase, or
        pilot data without its ratings (each named).
    """
    from analysis.power import power_table, variance_components
    from protocols import load_protocol

    subjects, reps = list(subjects), list(reps)
    if not subjects or min(subjects) < 2 or not reps or min(reps) < 1:
        raise UsageError("need at least 2 subjects and 1 repetition")
    p = load_protocol(protocol)
    rated = [ph for ph in p.phases if ph.design.analysed and ph.design.dv == "rating"]
    if not rated:
        raise UsageError(f"power: protocol {p.name!r} has no analysed rating phase; "
                         "power and precision are computed for rating studies")
    phase = rated[-1]
    comparisons = math.comb(len(phase.samples), 2)
    sd = {"sd_trial": 0.9 if sd_trial is None else sd_trial,
          "sd_interaction": sd_interaction, "sd_subject": sd_subject}
    if pilot:
        from analysis import LoadError, load_sessions

        try:
            d = load_sessions(pilot)
        except LoadError as exc:
            raise UsageError(str(exc)) from None
        # the phase the protocol's design analyses (a practice phase is a first look)
        d = d[d["valid"] & d["rating"].notna() & (d["protocol"] == p.name)
              & (d["phase"] == phase.name)]
        if d.empty:
            raise UsageError(f"--pilot {pilot}: no valid ratings of {p.name!r} "
                             f"in phase {phase.name!r}")
        try:
            sd = variance_components(d, sd_trial=sd_trial)
        except ValueError as exc:
            raise UsageError(f"--pilot {pilot}: {exc}") from None
    table = power_table(subjects, reps, effect, alpha=alpha, comparisons=comparisons,
                        experiments=experiments, **sd)
    return {"protocol": p.name, "phase": phase.name, "comparisons": comparisons, "sd": sd,
            "table": table}
