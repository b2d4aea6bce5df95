"""``hapticlab analyze``: the analyses the recorded designs call for → report.json / .md / .html.

Which sessions are pooled is chosen (:func:`analysis.load.select_sessions`) and shown: the
report opens with the table of sessions included and excluded, with the reason for each.
Sessions are grouped by the design they recorded; each analysed phase of each design gets
the analysis its design declares (:func:`analysis.analyses.analyse_phase`: each type's
numbers, methods, words, tables and figures are its module's), and its methods paragraph
is written from the data: the scale, the counts, the pairs and the corrections actually
applied. This module keeps the page: selection, summary, methods, sections, appendix.

Re-running on the same files gives identical numbers (the analyses have no randomness,
and the JSON is written with sorted keys and rounded floats).
"""

from __future__ import annotations

import hashlib
import html
import json
import math
import platform
import re
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

from .analyses import analyse_phase, analysis_type, report_entry
from .load import DEVICE_COLUMNS, load_sessions, select_sessions
from .report_text import md_text
from .report_text import table as _table
from .stats import StatsError
from .study import analysed_phases, phase_rows

__all__ = ["analyze", "build_report", "LISTED"]

#: told how far the work has got: (what, done, total)
Progress = Callable[[str, int, int], None]

SIMULATED_NOTE = (
    "These data come from simulated participants, not people: the ratings and answers "
    "are those of a rehearsal model (app/participant_model.py) that judges features of the "
    "simulated device's signals. Each simulated person taps with their own speed, grasp "
    "and rhythm, compares four felt features (stop time, jolt, onset pitch, ring-down) "
    "with the reference it felt, and places that distance on the range of what it has "
    "felt so far; the parameters are listed in app/participant_model.py and "
    "docs/explanation/simulated-participants.md. The report rehearses the study's "
    "analysis; its findings are not claims about human perception.")
DRY_RUN_NOTE = ("These data come from a dry run: a scripted responder answered at random to "
                "test the machinery. Nothing in this report is a finding.")


#: below this a p-value is not resolved by the distribution functions (the smallest
#: normal double); report.json gives the bound as text instead of a number
P_FLOOR = 2.3e-308



def _clean(v, where: str = "report"):
    """JSON-safe, finite, rounded (12 significant digits) values; a non-finite number is an
    error naming where it is."""
    if isinstance(v, dict):
        return {str(k): _clean(x, f"{where}.{k}") for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x, f"{where}[{i}]") for i, x in enumerate(v)]
    if isinstance(v, pd.DataFrame):
        return _clean(v.to_dict(orient="records"), where)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise ValueError(f"a non-finite number reached the report at {where}: {f}")
        return float(f"{f:.12g}")
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def _p_bounds(v, key: str = ""):
    """``v`` with every p-value that underflowed (below :data:`P_FLOOR`, 0 included) given
    as the bound it is, in words: report.json never says p = 0."""
    if isinstance(v, dict):
        return {k: _p_bounds(x, k) for k, x in v.items()}
    if isinstance(v, list):
        return [_p_bounds(x, key) for x in v]
    is_p = key == "p" or key.startswith("p_") or key.endswith("_p")
    if isinstance(v, float) and is_p and 0 <= v < P_FLOOR:
        return f"< {P_FLOOR:g}"
    return v


def _run(rows: pd.DataFrame, phase: dict):
    try:
        return analyse_phase(rows, phase)
    except StatsError as exc:
        return {"type": "not computed", "result": f"not computed: {exc}", "device": None}


#: a per-participant or per-session table of report.md and report.html is written out up
#: to this many rows; beyond, the page summarises it and says where the whole table is
#: (report.json, and sessions.tsv and input_files.tsv beside the report)
LISTED = 200


def build_report(data: pd.DataFrame, selection: pd.DataFrame, filters: dict,
                 progress: Progress | None = None) -> tuple[dict, list]:
    """Every analysis the selected sessions' designs call for; returns the report content (not
    yet cleaned) and the analyses with their full results (for the figures)."""
    designs = data.attrs.get("designs", {})
    analyses = []
    todo = [(key, phase) for key in sorted(set(data["design_key"]) - {""},
                                           key=lambda k: (designs[k]["protocol"], k))
            for phase in analysed_phases(designs[key])]
    for n, (key, phase) in enumerate(todo):
        design = designs[key]
        rows = phase_rows(data, key, phase["name"])
        if rows.empty:
            continue
        if progress is not None:
            progress(f"analysing {design['protocol']}/{phase['name']} ({len(rows):,} rows)",
                     n, len(todo))
        a = _run(rows, phase)
        a.update({"id": f"{design['protocol']}/{phase['name']}", "protocol":
                  design["protocol"], "phase": phase["name"], "design_key": key,
                  "phase_design": phase, "scale": design.get("scale")})
        title = f"{design.get('title') or design['protocol']} ({design['protocol']}), " \
                f"phase '{phase['name']}'"
        if isinstance(a["result"], str):
            a["entry"], a["methods"] = {"result": a["result"]}, f"{title}: {a['result']}."
        else:  # its own part of report.json, and its methods in its own words
            a["entry"], body = report_entry(analysis_type(a["type"]), a["result"], phase,
                                            design)
            a["methods"] = f"{title}: {body}"
        analyses.append(a)
    ids = [a["id"] for a in analyses]
    for a in analyses:  # the same protocol name under two designs: tell them apart
        if ids.count(a["id"]) > 1:
            a["id"] += f" (design {a['design_key'][:6]})"
    inc = selection[selection["included"]]
    kinds = sorted(set(inc["kind"]))
    intro = []
    if "simulated" in kinds:
        intro.append(SIMULATED_NOTE)
    if "dry-run" in kinds:
        intro.append(DRY_RUN_NOTE)
    shown = [f"{k}: {v}" for k, v in sorted(filters.items())
             if v and not (k == "ids" and v == "check")]  # the default check goes unsaid
    sel_text = (f"{len(inc)} of {len(selection)} sessions included ({', '.join(shown)}); "
                + ("every session found is listed below with the reason it is in or out."
                   if len(selection) <= LISTED else
                   "every session found is listed in sessions.tsv with the reason it is in or "
                   "out (below: the count of each kind, and those left out)."))
    methods = " ".join([*intro, sel_text, *(a["methods"] for a in analyses)])
    report = {
        "methods": methods, "kinds": kinds,
        "selection": {"filters": filters, "included": int(len(inc)),
                      "excluded": int(len(selection) - len(inc)),
                      "sessions": selection[["session_dir", "participant", "session",
                                             "protocol", "kind", "status", "rows", "included",
                                             "reason", *DEVICE_COLUMNS]].to_dict(
                                                 orient="records")},
        "analyses": [_report_entry(a) for a in analyses],
    }
    return report, analyses


def _report_entry(a: dict) -> dict:
    """An analysis in report.json: what every analysis has, then its type's own entry."""
    return {"id": a["id"], "protocol": a["protocol"], "phase": a["phase"], "type": a["type"],
            "design": a["phase_design"], "scale": a["scale"], "methods": a["methods"],
            "device": a["device"], **a["entry"]}


def analyze(data_dir: str | Path, out: str | Path, formats=("html", "md", "json"),
            protocol=None, kind=None, status: str = "complete", participants=None,
            since=None, until=None, drop_invalid: bool = False, ids: str = "check",
            sim_device: bool = False, progress: Progress | None = None) -> dict:
    """Select sessions, run every analysis their designs call for, write the report.

    Parameters
    ----------
    data_dir : path
        Folder of session folders.
    out : path
        Where report.json / report.md / report.html and the figures go.
    formats : tuple of {'html', 'md', 'json'}
    protocol, kind, status, participants, since, until, ids, sim_device
        Filters, as :func:`analysis.load.select_sessions`.
    drop_invalid : bool
        Leave out (and list) recorded rows that cannot be analysed, instead of stopping
        with an error naming the first (:func:`analysis.load.load_sessions`).
    progress : callable (step, done, total), optional
        Told how far the work has got: each session folder read, each analysis begun, the
        figures, the writing.

    Returns
    -------
    dict
        The report's content (what report.json holds). Beside report.*, ``sessions.tsv``
        lists every session found with the reason it is in or out, and ``input_files.tsv``
        the SHA-256 of every file read (the pages write them out up to :data:`LISTED` rows).
    """
    tell = progress or (lambda step, done, total: None)
    data = load_sessions(data_dir, drop_invalid=drop_invalid,
                         progress=lambda n, total: tell("loading sessions", n, total))
    filters = {"protocol": protocol, "kind": kind, "status": status,
               "participants": participants, "since": since, "until": until, "ids": ids,
               "sim_device": sim_device}
    tell("choosing the sessions", 0, 1)
    selected, table = select_sessions(data, **filters)
    filters = {**filters, "kind": kind or _default_kind(table)}
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    report, analyses = build_report(selected, table, filters, tell)
    figures = []
    if analyses:
        from .analyses import save_figures

        tell("drawing the figures", 0, 1)
        figures = save_figures(selected, analyses, out)
    tell("writing the report", 0, 1)
    inc = table[table["included"]]
    kept = set(inc["session_dir"])  # a file is the included session's whose folder holds it
    files = {k: v for k, v in data.attrs["files"].items()
             if str((Path(data_dir) / k).parent) in kept}
    report["figures"] = figures
    keep = set(inc["session_dir"])
    report["selection"]["rows_left_out"] = [
        r for r in data.attrs.get("invalid_rows", [])
        if str(Path(r["file"]).parent) in keep]
    report["provenance"] = {
        "packages": {p: _ver(p) for p in ("numpy", "scipy", "pandas", "statsmodels", "patsy",
                                          "matplotlib", "markdown-it-py")},
        "python": platform.python_version(), "input_files": files,
        "seeds": sorted({int(s) for s in inc["seed"] if s is not None}),
        "sessions": int(len(inc)), "torn_lines_set_aside": data.attrs["torn"]}
    report = _clean(report)
    _side_files(report, out)
    if "json" in formats:
        (out / "report.json").write_text(json.dumps(_p_bounds(report), indent=1,
                                                    sort_keys=True))
    md = _markdown(report)
    if "md" in formats:
        (out / "report.md").write_text(md)
    if "html" in formats:
        (out / "report.html").write_text(_html(md, report))
    return report


def _side_files(rep: dict, out: Path) -> None:
    """sessions.tsv (every session found, in or out, and why) and input_files.tsv (every
    file read, with its SHA-256): the whole of the tables the pages summarise beyond
    :data:`LISTED` rows, for a spreadsheet or a program."""
    pd.DataFrame(rep["selection"]["sessions"]).to_csv(out / "sessions.tsv", sep="\t",
                                                      index=False)
    pd.DataFrame(sorted(rep["provenance"]["input_files"].items()),
                 columns=["file", "sha256"]).to_csv(out / "input_files.tsv", sep="\t",
                                                    index=False)


def _sessions_md(sel: dict) -> list[str]:
    """The sessions found: the whole table up to :data:`LISTED` sessions; beyond, the count
    per protocol, kind and status, and the sessions left out (up to LISTED of them)."""
    cols = ["participant", "session", "protocol", "kind", "device_backend", "device_id",
            "firmware", "status", "rows", "included", "reason", "session_dir"]
    rows = sel["sessions"]
    if len(rows) <= LISTED:
        return [_table(rows, cols)]
    counts = (pd.DataFrame(rows).groupby(["protocol", "kind", "status", "included"])
              .size().reset_index(name="sessions"))
    out_ = [r for r in rows if not r["included"]]
    text = [f"{len(rows):,} sessions were found, more than the {LISTED} this page lists one "
            f"by one: every one of them, with the reason it is in or out, is in sessions.tsv "
            "beside this report (and in report.json).\n\n",
            _table(counts.to_dict(orient="records"))]
    if out_:
        shown = out_[:LISTED]
        text += [f"\n{len(out_):,} sessions were left out"
                 + (f"; the first {LISTED}" if len(out_) > LISTED else "") + ":\n\n",
                 _table(shown, cols)]
    return text


def _default_kind(table: pd.DataFrame) -> str:
    inc = table[table["included"]]
    return inc["kind"].iloc[0] if len(inc) else "human"


def _ver(p: str) -> str:
    try:
        return metadata.version(p)
    except metadata.PackageNotFoundError:
        return "not installed"


def _figures_of(a: dict, figures: list[str]) -> list[str]:
    """The PNG figures of analysis ``a``, named as :mod:`analysis.plots` names them."""
    from .plots import figure_prefix

    prefix = figure_prefix(a)
    return [f for f in figures if f.startswith(prefix) and f.endswith(".png")]


def _caption(name: str, kind: str) -> str:
    """The caption of figure file ``name`` of an analysis of type ``kind``: its type's, by
    the end of the name (``*``: any other, ``{group}`` the name's last part)."""
    stem = name.rsplit(".", 1)[0]
    captions = analysis_type(kind).captions
    for key, text in captions.items():
        if key != "*" and stem.endswith(key):
            return text
    if "*" in captions:
        return captions["*"].format(group=stem.rsplit("_", 1)[-1])
    return f"Figure {stem}."


def _summary(a: dict) -> str:
    """One paragraph of findings in words, with APA-style numbers."""
    if "result" in a:
        return f"**{md_text(a['id'])}**: {md_text(a['result'])}"
    return analysis_type(a["type"]).summary(a)


def _markdown(rep: dict) -> str:
    """The report: a summary of findings, methods, one section per analysis (key tables and
    its figures with captions), then an appendix with the long tables and provenance."""
    general = rep["methods"]
    for a in rep["analyses"]:
        general = general.replace(" " + a["methods"], "").replace(a["methods"], "")
    out = ["# hapticlab report\n", "## Summary of findings\n"]
    out += [f"- {_summary(a)}" for a in rep["analyses"]] or [
        "No analysed phase has data in the selected sessions."]
    out += ["", "## Methods\n", md_text(general) + "\n"]
    out.append("## Sessions included and excluded\n")
    out.extend(_sessions_md(rep["selection"]))
    appendix = []
    left_out = rep["selection"].get("rows_left_out") or []
    if left_out:
        out.append("\n### Recorded rows left out (--drop-invalid)\n")
        if len(left_out) > LISTED:
            out.append(f"{len(left_out):,} rows; the first {LISTED} (all in report.json, "
                       "selection.rows_left_out):\n\n")
        out.append(_table(left_out[:LISTED], ["participant", "phase", "sample", "reason",
                                              "file", "line"]))
    for a in rep["analyses"]:
        out.append(f"## {md_text(a['id'])}\n")
        out.append(md_text(a["methods"]) + "\n")
        if "result" in a:
            out.append(md_text(a["result"]) + "\n")
            continue
        main, app = analysis_type(a["type"]).markdown(a)
        out.extend(main)
        appendix.extend(app)
        d = a["device"]
        if d and d["n_taps"]:
            sp = d["saturations_per_participant"]
            out.append("\n#### Device\n")
            out.append(f"Incoming speed over {d['n_taps']} valid taps: "
                       f"{d['velocity_mean']:.3f} ± {d['velocity_sd'] or 0:.3f} m/s (mean ± SD). "
                       f"Saturations per participant: mean {sp['mean']:.2f}, range "
                       f"{sp['min']}–{sp['max']}.\n\n")
            if d["saturations_per_sample"]:
                out.append(_table([{"sample": k, "saturations": v}
                                   for k, v in d["saturations_per_sample"].items()]))
        for f in _figures_of(a, rep["figures"]):
            cap = md_text(_caption(f, a["type"]))
            out.append(f"\n![{cap}](<{f}>)\n")
            out.append(f"*Figure: {cap}*\n")
    out.append("\n## Appendix\n")
    out.extend(appendix)
    p = rep["provenance"]
    out.append("\n### Provenance\n")
    out.append(f"Python {p['python']}; " + ", ".join(f"{k} {v}" for k, v in
                                                     p["packages"].items()) + ".\n\n")
    out.append(f"Seeds: {p['seeds']}. Sessions: {p['sessions']}. Torn lines set aside: "
               f"{len(p['torn_lines_set_aside'])}.\n\n")
    files = sorted(p["input_files"].items())
    if len(files) > LISTED:
        digest = hashlib.sha256("".join(f"{k}\t{v}\n" for k, v in files).encode()).hexdigest()
        out.append(f"{len(files):,} files were read; the SHA-256 of each is in "
                   f"input_files.tsv beside this report and in report.json (SHA-256 of the "
                   f"list, one 'file<TAB>sha256' line each: {digest}).\n")
    else:
        out.append(_table([{"file": k, "sha256": v} for k, v in files]))
    return "\n".join(out)


#: tables longer than this are collapsed in the HTML (a click shows them)
COLLAPSE_ROWS = 12


def _collapse(match: re.Match) -> str:
    rows = match.group(0).count("<tr>") - 1  # the header row
    if rows > COLLAPSE_ROWS:
        return f"<details><summary>{rows} rows (show)</summary>{match.group(0)}</details>"
    return match.group(0)


def _html(md: str, rep: dict) -> str:
    """A self-contained page: the Markdown rendered by markdown-it-py (CommonMark with
    tables; raw HTML in the Markdown is shown as text, never interpreted), long tables
    collapsed."""
    from markdown_it import MarkdownIt

    body = MarkdownIt("commonmark", {"html": False}).enable("table").render(md)
    body = re.sub(r"<table>.*?</table>", _collapse, body, flags=re.S)
    body = re.sub(r"<h(\d)>(.*?)</h\1>", lambda m: '<h{0} id="{1}">{2}</h{0}>'.format(
        m.group(1), re.sub(r"[^0-9a-z]+", "-", html.unescape(m.group(2)).lower()).strip("-"),
        m.group(2)), body)  # anchors a reader can link to
    digest = hashlib.sha256(json.dumps(rep, sort_keys=True).encode()).hexdigest()[:16]
    style = ("body{font-family:sans-serif;max-width:1000px;margin:auto;line-height:1.4}"
             "table{border-collapse:collapse;font-size:12px;margin:6px 0}"
             "td,th{border:1px solid #ccc;padding:2px 6px}th{background:#f3f3f3}"
             "img{max-width:100%}"
             "h2{border-bottom:1px solid #ccc;margin-top:28px}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>hapticlab report</title>"
            f"<style>{style}</style></head><body>{body}<p><small>report digest "
            f"{digest}</small></p></body></html>")
