"""``hapticlab analyze``: every study found in a data folder → report.json / .md / .html + figures.

Re-running on the same files gives identical numbers (the analyses have no randomness,
and the JSON is written with sorted keys and rounded floats).
"""

from __future__ import annotations

import hashlib
import html
import json
import math
import platform
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

from .load import load_sessions
from .stats import StatsError
from .study import device_summary, factorial, identification, realism

__all__ = ["analyze", "METHODS"]

METHODS = (
    "Ratings were averaged per participant and sample before testing. Realism ratings "
    "(1–7) of the testing phase were compared with a one-way repeated-measures ANOVA "
    "(sample as the within-subject factor; sphericity by Mauchly's test, corrections by "
    "Greenhouse–Geisser and Huynh–Feldt ε; effect sizes partial η² and generalized η², "
    "Olejnik & Algina 2003) and with paired two-sided t-tests on every pair of samples "
    "(55 pairs for 11 samples), p-values adjusted by Holm–Bonferroni and, separately, by "
    "Benjamini–Hochberg; effect size d_z = mean difference / SD of the differences; 95 % "
    "confidence intervals of mean differences from the t distribution. Samples whose "
    "Holm-adjusted p ≥ .05 are grouped as not distinguishable (connected pairs). "
    "Factorial ratings (1–10) were z-scored within each participant (mean 0, SD 1; a "
    "participant with constant ratings gets z = 0) and analysed per material with a 2×2×2 "
    "repeated-measures ANOVA (frequency, decay rate, amplitude slope); the most significant "
    "parameter is the main effect with the smallest p; the best set is the set with the "
    "highest mean z. Identification answers count as correct only when all three surfaces "
    "were named right; chance is 1/6 (3! orders); percent correct is tested against chance "
    "with a one-sided exact binomial test. Participants missing a cell are excluded from "
    "repeated-measures tests (listwise); every exclusion is listed below.")


SIMULATED_NOTE = (
    "These data come from simulated participants, not people: the ratings and answers "
    "are those of a rehearsal model (app/simulated.py) that judges features of the "
    "simulated device's signals. Each simulated person taps with their own speed, grasp "
    "and rhythm, compares four felt features (stop time, jolt, onset pitch, ring-down) "
    "with the reference it felt, and places that distance on the range of what it has "
    "felt so far; the parameters are listed in app/simulated.py and the README. The "
    "report rehearses the study's analysis; its findings are not claims about human "
    "perception.")


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


def _section(fn, *args):
    try:
        return fn(*args)
    except StatsError as exc:
        return f"not computed: {exc}"


def analyze(data_dir: str | Path, out: str | Path, formats=("html", "md", "json")) -> dict:
    """Run every analysis the data allows and write the report; returns the JSON content."""
    data = load_sessions(data_dir)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    protos = set(data["protocol"])
    res: dict = {}
    if "realism" in protos:
        res["realism"] = _section(realism, data)
    if "factorial" in protos:
        res["factorial"] = _section(factorial, data)
    if "identification" in protos:
        res["identification"] = _section(identification, data)
    res["device"] = device_summary(data)
    figures = []
    try:
        from .plots import save_all

        figures = save_all(data, res, out)
    except ImportError:
        pass
    prov = {"packages": {p: _ver(p) for p in ("numpy", "scipy", "pandas", "matplotlib")},
            "python": platform.python_version(),
            "input_files": data.attrs["files"], "seeds": sorted({int(s) for s in data["seed"]
                                                                 if s is not None}),
            "sessions": data.attrs["sessions"], "torn_lines_set_aside": data.attrs["torn"]}
    responders = sorted(set(data["responder"])) if "responder" in data else []
    prov["responders"] = responders
    methods = METHODS
    if any(r != "person" for r in responders):
        methods = (f"{SIMULATED_NOTE} (responders: {', '.join(responders)}.) " + METHODS)
    report = {"methods": methods, "provenance": prov, "figures": figures,
              "device": res["device"]}
    if "realism" in res:
        r = res["realism"]
        report["realism"] = r if isinstance(r, str) else {
            "samples": r["samples"], "anova": r["anova"], "groups": r["groups"],
            "pairwise": r["pairwise"][["A", "B", "mean_diff", "ci_low", "ci_high", "t", "dof",
                                       "p_unc", "p_holm", "p_fdr", "p_corr", "dz"]],
            "anova_notes": r["anova"].attrs.get("notes", []),
            "session_length": r["session_length"],
            "n_subjects": r["n_subjects"], "exclusions": r["preflight"],
            "constant_pairs": [list(p) for p in r["constant_pairs"]],
            # a participant without a valid rating of a sample (every attempt saturated)
            # has no mean there: null, and listed among the exclusions
            "per_subject": [{k: (None if isinstance(x, float) and math.isnan(x) else x)
                             for k, x in row.items()}
                            for row in r["per_subject"].to_dict(orient="records")]}
    if "factorial" in res:
        f = res["factorial"]
        report["factorial"] = f if isinstance(f, str) else {
            m: {"anova": v["anova"], "most_significant": v["most_significant"],
                "best_set": v["best_set"], "main_effects": v["main_effects"],
                "sets": v["sets"], "exclusions": v["preflight"],
                "n_subjects": v["n_subjects"]} for m, v in f.items()}
    if "identification" in res:
        i = res["identification"]
        report["identification"] = i if isinstance(i, str) else {
            "table": i["table"], "chance": i["chance"], "n_subjects": i["n_subjects"],
            "confusion": None if i["confusion"] is None else
            {k: {kk: int(vv) for kk, vv in row.items()} for k, row in
             i["confusion"].to_dict(orient="index").items()}}
    report = _clean(report)
    if "json" in formats:
        (out / "report.json").write_text(json.dumps(report, indent=1, sort_keys=True))
    md = _markdown(report)
    if "md" in formats:
        (out / "report.md").write_text(md)
    if "html" in formats:
        (out / "report.html").write_text(_html(md, report))
    return report


def _ver(p: str) -> str:
    try:
        return metadata.version(p)
    except metadata.PackageNotFoundError:
        return "not installed"


def _table(rows: list[dict], cols: list[str] | None = None) -> str:
    if not rows:
        return "_none_\n"
    cols = cols or list(rows[0])

    def fmt(v):
        if v is None:
            return "—"
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(fmt(r.get(c, "")) for c in cols) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _markdown(rep: dict) -> str:
    out = ["# hapticlab report\n", "## Methods\n", rep["methods"] + "\n"]
    if "realism" in rep:
        r = rep["realism"]
        out.append("## Realism\n")
        if isinstance(r, str):
            out.append(r + "\n")
        else:
            out.append(f"{r['n_subjects']} participants.\n\n### Samples (mean rating, 95 % CI; "
                       "z: per-participant z-scores)\n")
            out.append(_table(r["samples"]))
            out.append("\n### One-way repeated-measures ANOVA\n")
            out.append(_table(r["anova"]))
            out.extend(f"\n_{note}._\n" for note in r["anova_notes"])
            out.append("\n### Groups not distinguishable (Holm p ≥ .05)\n")
            out.append("\n".join("- " + ", ".join(g) for g in r["groups"]) + "\n")
            out.append("\n### Paired t-tests (d_z: Cohen's d for paired data)\n")
            out.append(_table(r["pairwise"]))
            out.append("\n### Exclusions\n")
            out.append(_table(r["exclusions"]))
            sl = r["session_length"]
            vc = sl["variance_components"]
            out.append("\n### Session length against power and precision\n")
            out.append(f"Monte-Carlo, 10⁴ simulated studies per cell, with this study's SDs "
                       f"(trial {vc['sd_trial']:.2f}, participant×sample "
                       f"{vc['sd_interaction']:.2f}, participant {vc['sd_subject']:.2f}): "
                       f"power of a {sl['effect']:g}-point paired difference (Bonferroni over "
                       "all pairs) and the median 95 % CI half-width of a sample's mean.\n\n")
            out.append(_table(sl["table"], ["subjects", "reps", "power", "ci_halfwidth"]))
    if "factorial" in rep:
        out.append("## Factorial study\n")
        f = rep["factorial"]
        if isinstance(f, str):
            out.append(f + "\n")
        else:
            rows = [{"material": m, **v["best_set"], "most significant": v["most_significant"]}
                    for m, v in f.items()]
            out.append("### Best set per material (cf. the paper's Table 2)\n")
            out.append(_table(rows))
            for m, v in f.items():
                out.append(f"\n### {m}: preferred level of each parameter (mean z)\n")
                out.append(_table(v["main_effects"]))
                out.append(f"\n### {m}: 2×2×2 ANOVA on z-scores\n")
                out.append(_table(v["anova"]))
    if "identification" in rep:
        out.append("## Identification (cf. the paper's Table 3)\n")
        i = rep["identification"]
        if isinstance(i, str):
            out.append(i + "\n")
        else:
            out.append(f"Chance: 1/6 = {100 * i['chance']:.1f} %.\n\n")
            out.append(_table(i["table"]))
            if i["confusion"]:
                out.append("\n### Confusion (rows presented, columns answered)\n")
                names = list(i["confusion"])
                out.append(_table([{"presented": k, **i["confusion"][k]} for k in names]))
    d = rep["device"]
    out.append("## Device\n")
    out.append(f"Incoming speed over {d['n_taps']} valid taps: {d['velocity_mean']:.4f} ± "
               f"{d['velocity_sd']:.4f} m/s (mean ± SD). Saturations per participant: mean "
               f"{d['saturations_per_participant']['mean']:.2f}, range "
               f"{d['saturations_per_participant']['min']}–"
               f"{d['saturations_per_participant']['max']}.\n\n")
    out.append(_table([{"sample": k, "saturations": v}
                       for k, v in d["saturations_per_sample"].items()]))
    out.append("\n## Figures\n")
    out += [f"![{f}]({f})\n" for f in rep["figures"] if f.endswith(".png")]
    p = rep["provenance"]
    out.append("\n## Provenance\n")
    out.append(f"Python {p['python']}; " + ", ".join(f"{k} {v}" for k, v in
                                                     p["packages"].items()) + ".\n\n")
    out.append(f"Seeds: {p['seeds']}. Sessions: {p['sessions']}. Torn lines set aside: "
               f"{len(p['torn_lines_set_aside'])}.\n\n")
    out.append(_table([{"file": k, "sha256": v} for k, v in sorted(p["input_files"].items())]))
    return "\n".join(out)


def _html(md: str, rep: dict) -> str:
    """A self-contained page: the Markdown's text, tables and images as HTML."""
    body, in_table, rows = [], False, []
    for line in md.splitlines():
        if line.startswith("|"):
            if set(line.replace("|", "").strip()) <= {"-"}:
                continue
            rows.append([html.escape(c.strip()) for c in line.strip("|").split("|")])
            in_table = True
            continue
        if in_table:
            head, *rest = rows
            body.append("<table><tr>" + "".join(f"<th>{c}</th>" for c in head) + "</tr>"
                        + "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>"
                                  for r in rest) + "</table>")
            rows, in_table = [], False
        if line.startswith("#"):
            n = len(line) - len(line.lstrip("#"))
            body.append(f"<h{n}>{html.escape(line[n:].strip())}</h{n}>")
        elif line.startswith("!["):
            src = line[line.index("(") + 1: line.rindex(")")]
            body.append(f'<img src="{html.escape(src)}" style="max-width:100%">')
        elif line.startswith("- "):
            body.append(f"<li>{html.escape(line[2:])}</li>")
        elif line.strip():
            body.append(f"<p>{html.escape(line)}</p>")
    digest = hashlib.sha256(json.dumps(rep, sort_keys=True).encode()).hexdigest()[:16]
    style = ("body{font-family:sans-serif;max-width:1000px;margin:auto}table{border-collapse:"
             "collapse;font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>hapticlab report</title>"
            f"<style>{style}</style></head><body>{''.join(body)}<p><small>report digest "
            f"{digest}</small></p></body></html>")
