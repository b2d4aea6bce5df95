"""Exports for analysts who continue elsewhere (JASP, SPSS, R), with a codebook.

The rows are those the report analyses: the same session selection
(:func:`analysis.load.select_sessions`) and, per analysed phase, its valid trials.

Formats
-------
``long-csv``
    ``long.csv``: one row per analysed trial.
``wide-csv``
    ``wide_<protocol>_<phase>.csv`` per analysed phase: one row per participant, one column
    per cell (the participant's mean of the phase's dependent variable over its
    repetitions; empty where the participant has none), as SPSS and JASP expect for
    repeated measures. Participants missing a cell are kept (an empty cell); the report's
    listwise analyses leave them out.
``jasp``
    The wide files, with column names JASP and R read unchanged (letters, digits and
    ``_``), and the participant's group as a column for a between-subject factor.
``r``
    ``long.csv`` and ``load.R``, which reads it with every factor's levels in the order the
    protocol declares them.
``spss``
    The wide files and the long file as SPSS ``.sav`` (pyreadstat): variable labels from
    the codebook, value labels for low/high factors and for ``correct``.
``bids``
    A BIDS dataset (behavioural modality): every attempt of the chosen sessions with its
    onset, and the device's traces of each window kept in full (:mod:`analysis.bids`; no
    codebook: the JSON sidecars describe every column).

Every format but ``bids`` (whose JSON sidecars describe its columns) writes
``codebook.csv``: column, type (text or number), unit, meaning (and,
for renamed columns, the original name). CSV files quote every text cell, but quotes do not
stop pandas, R's ``read.csv`` or JASP from reading a participant id ``001`` as the number 1:
only a reader told the column is text keeps it. So the CSV formats also write ``load.py``
(pandas: each CSV with the codebook's text columns read as text), and ``r`` writes
``load.R``; in JASP, set the participant column to nominal text by hand.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pandas as pd

from .cells import column_meanings, recorded_response, response_columns
from .load import DEVICE_COLUMNS, load_sessions, select_sessions
from .study import analysed_phases, phase_rows

__all__ = ["export", "FORMATS", "LONG_COLUMNS"]

FORMATS = ("long-csv", "wide-csv", "jasp", "r", "spss", "bids")

#: column → (unit, meaning) of the long file.
LONG_COLUMNS = {
    "participant": ("", "participant id as entered at the session (text: 001 stays 001)"),
    "group": ("", "participant group (e.g. expert, novice); empty when none was given"),
    "session": ("", "session number of this participant (ses-N)"),
    "protocol": ("", "protocol name"),
    "phase": ("", "phase of the protocol"),
    "block": ("", "block (factorial material); empty when the phase has no blocks"),
    "sample": ("", "sample id (a rendering or real sample; factorial sets are "
                   "<material>-<code>, one letter per factor in the order frequency, decay, "
                   "slope, L low and H high: rubber-LHL is low frequency, high decay, low "
                   "slope; identification: the surfaces in order, joined by +; "
                   "comparison: the two samples in the order felt, joined by +)"),
    "repetition": ("", "1-based repetition of the sample within its phase"),
    "trial_index": ("", "1-based position of the attempt in the session"),
    # a response's columns (rating, answer, correct, response_time, …) take their unit and
    # meaning from the responses the exported phases recorded (_response_meanings); these
    # are for a column no exported phase's response fills
    "rating": ("scale points", "the participant's rating on the protocol's scale"),
    "rating_z": ("SD", "the rating z-scored within the participant (factorial: within "
                       "participant and block), SD with divisor n: the dependent variable of "
                       "the factorial ANOVA; empty where the participant gave one rating "
                       "throughout (z undefined; the report leaves them out)"),
    "frequency_hz": ("Hz", "factorial set: the vibration's frequency"),
    "decay_per_s": ("1/s", "factorial set: the vibration's decay rate"),
    "slope_per_s": ("1/s", "factorial set: the amplitude slope (peak acceleration per "
                           "incoming speed)"),
    "scale": ("", "the rating scale, min-max"),
    "answer": ("", "the participant's answer"),
    "correct": ("0/1", "1 when the answer was right"),
    "track": ("", "adaptive phases: the track (<standard>-<up|down>)"),
    "intensity": ("the phase's units", "adaptive phases: the intensity presented"),
    "state": ("", "adaptive phases: the procedure after the answer (JSON)"),
    "reversal": ("0/1", "adaptive phases: 1 where the staircase reversed after this answer"),
    "catch": ("0/1", "adaptive phases: 1 for a catch trial (at the catch intensity, not "
                     "given to the procedure)"),
    "response_time": ("s", "from the answer screen's onset to the answer"),
    "n_taps": ("", "contacts in the trial's window"),
    "mean_tap_velocity": ("m/s", "mean incoming speed of the trial's taps"),
    "peak_current": ("A", "largest commanded current in the window"),
    "kind": ("", "session kind: human (a person), dry-run or simulated"),
    "device_backend": ("", "the device the session ran on: sim is the simulated device (no "
                           "physical contact: a rehearsal even with a person), serial a "
                           "device on a serial port"),
    "device_id": ("", "the device's model and serial number (#…), as it reported them"),
    "firmware": ("", "the device's firmware version, as it reported it"),
    "simulated_plant": ("0/1", "1: the device said its contact was simulated (the "
                               "simulated device, the emulator, a firmware build with its "
                               "simulated plant, a bridge over an SDK's stand-in): nobody "
                               "touched a physical surface"),
    "libraries": ("", "transient libraries played: sample=sha256 of the file (first 12 hex "
                      "digits), joined by ;"),
}


#: the long file's columns of adaptive phases, left out of an export without one
_ADAPTIVE_COLUMNS = ("track", "intensity", "state", "reversal", "catch")

#: what the export adds to a response column's recorded meaning: the analyses it feeds
_USES = {"rating": "the dependent variable of the one-way analyses (ANOVA, t-tests, Wilcoxon, "
                   "Friedman, mixed and ordinal models)"}


def _response_meanings(parts) -> tuple[dict[str, tuple[str, str]], dict[str, dict]]:
    """(column → (unit, meaning), column → value labels) of the response columns the
    exported phases fill (:func:`analysis.cells.column_meanings`), with what the export
    adds of the analyses they feed."""
    meanings, labels = column_meanings([phase for _design, phase, _rows in parts])
    return {c: (u, f"{m}: {_USES[c]}" if c in _USES else m)
            for c, (u, m) in meanings.items()}, labels


def _safe(name: str) -> str:
    """A column name JASP, SPSS and R read unchanged: letters, digits and _."""
    s = re.sub(r"[^0-9A-Za-z_]+", "_", str(name)).strip("_")
    return s if s and not s[0].isdigit() else f"x_{s}"


def _analysed(data: pd.DataFrame) -> list[tuple[dict, dict, pd.DataFrame]]:
    """(design, phase, its valid trials) for every analysed phase, in report order."""
    designs = data.attrs.get("designs", {})
    out = []
    for key in sorted(set(data["design_key"]) - {""}, key=lambda k: (designs[k]["protocol"], k)):
        design = designs[key]
        for phase in analysed_phases(design):
            rows = phase_rows(data, key, phase["name"])
            rows = rows[rows["valid"]]
            if not rows.empty:
                out.append((design, phase, rows))
    return out


def _z(rows: pd.DataFrame, phase: dict) -> pd.Series:
    """The ratings z-scored within the participant (and block, for ``zscore_block``), SD
    with divisor n; NaN where the unit has one rating throughout (undefined)."""
    from .stats import zscore_by_subject

    if "rating" not in rows or rows["rating"].isna().all():
        return pd.Series(np.nan, index=rows.index)
    unit = rows["participant"].astype(str)
    if phase.get("normalize") == "zscore_block":
        unit = unit + "\x1f" + rows["block"].astype(str)
    r = rows.assign(_unit=unit.to_numpy())
    z = zscore_by_subject(r, "rating", "_unit")
    v = pd.to_numeric(r["rating"], errors="coerce")
    flat = v.groupby(r["_unit"]).transform("max") == v.groupby(r["_unit"]).transform("min")
    return z.where(~flat)


def _mean_of_lists(col: pd.Series) -> pd.Series:
    """The mean of each cell's ';'-separated numbers (NaN for an empty cell), for all rows
    at once (a Series per row cost a minute at 10⁶ rows)."""
    each = col.fillna("").astype(str).str.split(";").explode()
    values = pd.to_numeric(each.replace("", np.nan), errors="coerce")
    return values.groupby(level=0).mean().reindex(col.index)


def _joined(r: pd.DataFrame, column: str) -> pd.Series:
    """Each participant's distinct values of ``column`` in order, joined by '|' (most have
    one: those are taken as they are, without a call per participant)."""
    pairs = r[["participant", column]].fillna("").astype({column: str}).drop_duplicates()
    several = pairs["participant"].duplicated(keep=False)
    one = pairs[~several].set_index("participant")[column]
    many = pairs[several].groupby("participant", sort=False)[column].agg("|".join)
    return pd.concat([one, many])


def _long(parts) -> pd.DataFrame:
    frames = []
    for _design, phase, rows in parts:
        f = rows.copy()
        f.attrs = {}  # the loader's tables travel in attrs; concat compares them
        factors = list(phase.get("within", []))
        f["mean_tap_velocity"] = _mean_of_lists(f["tap_velocities"])
        f["rating_z"] = _z(f, phase)
        if phase.get("adaptive"):  # what each state says, as columns any reader takes
            from .thresholds import states

            st = states(f)
            f["reversal"] = [int(bool(s.get("reversal"))) for s in st]
            f["catch"] = [int(bool(s.get("catch"))) for s in st]
        params = {sid: (v or {}).get("params") or {}
                  for sid, v in (_design.get("samples") or {}).items()}
        for name, col in (("frequency", "frequency_hz"), ("decay", "decay_per_s"),
                          ("slope", "slope_per_s")):
            vals = f["sample"].map({sid: p.get(name) for sid, p in params.items()})
            if vals.notna().any():
                f[col] = pd.to_numeric(vals, errors="coerce").abs()
        cols = [c for c in LONG_COLUMNS if c in f.columns]
        cols += [c for c in factors if c in f.columns and c not in cols]
        frames.append(f[cols])
    out = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=[*LONG_COLUMNS])
    if "group" in out and not out["group"].fillna("").astype(str).str.len().gt(0).any():
        out = out.drop(columns="group")  # no participant has a group: no empty column
    if not any(phase.get("adaptive") for _d, phase, _r in parts):  # no adaptive phase: none
        out = out.drop(columns=[c for c in _ADAPTIVE_COLUMNS if c in out])
    return out.sort_values(["protocol", "phase", "participant", "session", "trial_index"],
                           kind="stable").reset_index(drop=True)


def _chosen(rows: pd.DataFrame, value: str) -> pd.DataFrame:
    """Trials of several samples as one row per sample felt: ``sample`` and ``chosen`` (1
    when ``value`` named it), so a participant's mean of ``chosen`` per sample is the share
    of that sample's trials that chose it (a comparison: the share it won)."""
    rows = rows.copy()
    rows.attrs = {}  # the loaded data's (designs, files): not the rows', and concat compares
    felt = rows["sample"].str.split("+", expand=True)
    parts = [rows.assign(sample=felt[i], chosen=(rows[value] == felt[i]).astype(float))
             for i in range(felt.shape[1])]
    return pd.concat(parts, ignore_index=True)


def _thresholds(rows: pd.DataFrame, phase: dict) -> pd.DataFrame:
    """An adaptive phase's thresholds, one row per participant and track (as the report
    fits them, without the bootstrap of their goodness of fit), with each participant's
    group and device columns."""
    from .thresholds import threshold_scores

    fits = pd.DataFrame(threshold_scores(rows, phase, gof_samples=0)["fits"])
    keep = [c for c in ("participant", "group", *DEVICE_COLUMNS) if c in rows]
    people = rows[keep].drop_duplicates("participant").assign(
        participant=lambda d: d["participant"].astype(str))
    return fits[["participant", "track", "threshold"]].merge(people, on="participant",
                                                              how="left")


def _wide(design: dict, phase: dict, rows: pd.DataFrame, safe: bool) -> tuple[pd.DataFrame, dict]:
    """One row per participant, one column per cell, as the phase's recorded response says
    (:data:`protocols.responses.WIDE_BY`); returns (table, column → meaning)."""
    spec = recorded_response(phase)["wide"]
    dv, cell = spec["value"], "repetition" if spec["by"] == "repetition" else "sample"
    if spec["by"] == "chosen":
        rows, dv = _chosen(rows, dv), "chosen"
    elif spec["by"] == "track":
        rows, dv, cell = _thresholds(rows, phase), "threshold", "track"
    vals = pd.to_numeric(rows[dv], errors="coerce")
    r = rows.assign(**{dv: vals}).dropna(subset=[dv])
    w = (r.groupby(["participant", cell], observed=True)[dv].mean().unstack(cell))
    present = set(r[cell])
    order = ([x for x in phase.get("samples", []) if x in present]  # the protocol's order
             + sorted(present - set(phase.get("samples", [])), key=str)
             if cell == "sample" else
             [t["name"] for t in (phase.get("adaptive") or {}).get("tracks", [])
              if t["name"] in present] if cell == "track" else sorted(present))
    w = w.reindex(columns=order)
    normalized = phase.get("normalize") in ("zscore", "zscore_block")
    if normalized:  # the factorial ANOVA's dependent variable, beside the raw means
        z = r.assign(_z=_z(r, phase)).groupby(["participant", cell], observed=True)["_z"]
        wz = z.mean().unstack(cell).reindex(columns=order)
        wz.columns = [f"{c}_z" for c in order]
        w = w.join(wz)
    groups = r.groupby("participant", observed=True)["group"].first().fillna("").astype(str)
    if groups.str.len().gt(0).any():
        w.insert(0, "group", groups.reindex(w.index).fillna(""))
    for c in reversed(DEVICE_COLUMNS):  # what each person tapped on (several: joined by |)
        if c in r:
            w.insert(0, c, _joined(r, c).reindex(w.index).fillna(""))
    w = w.reset_index()
    meaning = {"participant": ("", "participant id (text)"),
               "group": ("", "participant group (between-subject factor); empty when none"),
               **{c: LONG_COLUMNS[c] for c in DEVICE_COLUMNS if c in w.columns}}
    rename = {}
    scale = design.get("scale") or {}
    unit = spec["unit"]
    if response_columns(phase).get(spec["value"], {}).get("range") == "scale" and scale:
        unit = f"{unit} ({scale['min']}–{scale['max']})"
    if cell == "track":  # an adaptive phase's thresholds: in its units, at its criterion
        unit = (phase.get("adaptive") or {}).get("units", unit)
        spec = {**spec, "meaning": spec["meaning"].replace(
            "the phase's criterion",
            f"{100 * (phase.get('fit') or {}).get('criterion', 0.75):g} % correct")}
    for c in order:
        name = spec["name"].format(cell=c)
        new = _safe(name) if safe else name
        rename[c] = new
        what = spec["meaning"].format(cell=c)
        meaning[new] = (unit, what + ("" if new == str(name) else f" (column {name})"))
        if normalized:
            zname = _safe(f"{name}_z") if safe else f"{name}_z"
            rename[f"{c}_z"] = zname
            meaning[zname] = ("SD", f"mean rating_z of sample {c}: the factorial ANOVA's "
                                    "dependent variable (a repeated-measures ANOVA on a "
                                    "block's _z columns gives the report's F and p)")
    if "group" not in w.columns:
        meaning.pop("group")
    w = w.rename(columns=rename)
    return w, meaning


def _long_entries(columns, answers: dict) -> dict[str, tuple[str, str]]:
    """The long file's codebook: a response column's recorded meaning, the others' from
    :data:`LONG_COLUMNS`, a factor's by its name."""
    return {c: answers.get(c) or LONG_COLUMNS.get(c, ("", f"level of factor {c} (low/high)"))
            for c in columns}


def _write_sav(path: Path, table: pd.DataFrame, meaning: dict[str, tuple[str, str]],
               value_labels: dict[str, dict] | None = None) -> None:
    """An SPSS file (pyreadstat) whose variable labels are the codebook's meanings (with
    units) and whose low/high columns, and response columns with value labels (``correct``),
    carry value labels."""
    import pyreadstat

    labels = {c: (f"{m} [{u}]" if u else m)[:255] for c, (u, m) in meaning.items()
              if c in table.columns}
    values: dict[str, dict] = {}
    t = table.copy()
    for c in t.columns:
        col = t[c]
        if c in (value_labels or {}):
            values[c] = {float(k) if _number(k) else k: v for k, v in value_labels[c].items()}
        elif (col.dtype == object or pd.api.types.is_string_dtype(col)) and \
                set(col.dropna().astype(str)) - {""} == {"low", "high"}:
            t[c] = col.map({"low": 1, "high": 2})  # anything else (empty) is missing
            values[c] = {1: "low", 2: "high"}
        elif col.dtype == bool:
            t[c] = col.astype(int)
    pyreadstat.write_sav(t, str(path), column_labels=labels, variable_value_labels=values)


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _type(col: pd.Series) -> str:
    """``number`` or ``text``: how a reader must take the column (a participant id ``001``
    is text, and stays so only when read as text)."""
    return ("number" if pd.api.types.is_numeric_dtype(col)
            and not pd.api.types.is_bool_dtype(col) else "text")


def _write_codebook(table: pd.DataFrame, entries: dict[str, tuple[str, str]],
                    file: str) -> list[dict]:
    return [{"file": file, "column": c, "type": _type(table[c]) if c in table else "text",
             "unit": u, "meaning": m} for c, (u, m) in entries.items()]


def _write_csv(table: pd.DataFrame, path: Path) -> None:
    """Text quoted, numbers bare (a reader that honours quotes keeps ``001`` as typed;
    codebook.csv's ``type`` says which columns are text for those that do not). A missing
    text cell is written ``""``, which R and pandas read as missing."""
    t = table.copy()
    for c in t.columns:  # every text cell a string: quoted (empty cells stay empty)
        if _type(t[c]) == "text":
            t[c] = t[c].map(lambda v: "" if v is None or (isinstance(v, float) and v != v)
                            else str(v))
    t.to_csv(path, index=False, quoting=csv.QUOTE_NONNUMERIC)


def export(data_dir: str | Path, out: str | Path, fmt: str = "long-csv",
           drop_invalid: bool = False, progress=None, **filters) -> list[Path]:
    """Write the analysed trials of ``data_dir`` to ``out`` in format ``fmt``.

    Parameters
    ----------
    data_dir : path
        Folder of session folders.
    out : path
        Folder to write into (created).
    fmt : {'long-csv', 'wide-csv', 'jasp', 'r'}
    drop_invalid : bool
        As :func:`analysis.report.analyze`.
    progress : callable (step, done, total), optional
        Told how far the work has got (as :func:`analysis.report.analyze`).
    **filters
        protocol, kind, status, participants, since, until, ids, sim_device: as the report.

    Returns
    -------
    list of Path
        The files written (``codebook.csv`` last).
    """
    if fmt not in FORMATS:
        raise ValueError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "bids":  # every attempt of the chosen sessions, raw: analysis/bids.py
        from .bids import export_bids

        return export_bids(data_dir, out, progress=progress, **filters)["files"]
    tell = progress or (lambda step, done, total: None)
    data = load_sessions(data_dir, drop_invalid=drop_invalid,
                         progress=lambda n, total: tell("loading sessions", n, total))
    tell(f"writing {fmt}", 0, 1)
    selected, _table = select_sessions(data, **{k: v for k, v in filters.items()
                                                if v is not None})
    parts = _analysed(selected)
    answers, labels = _response_meanings(parts)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written, book = [], []
    if fmt != "spss":  # CSV files: a reader that keeps text as text
        p = out / "load.py"
        p.write_text(_PY_LOADER)
        written.append(p)
    if fmt in ("long-csv", "r"):
        long = _long(parts)
        p = out / "long.csv"
        _write_csv(long, p)
        written.append(p)
        entries = _long_entries(long.columns, answers)
        book += _write_codebook(long, entries, p.name)
        if fmt == "r":
            p = out / "load.R"
            p.write_text(_r_script(long, parts))
            written.append(p)
    else:
        for design, phase, rows in parts:
            w, meaning = _wide(design, phase, rows, safe=fmt in ("jasp", "spss"))
            ext = "sav" if fmt == "spss" else "csv"
            name = f"wide_{_safe(design['protocol'])}_{_safe(phase['name'])}.{ext}"
            p = out / name
            if fmt == "spss":
                _write_sav(p, w, meaning, labels)
            else:
                _write_csv(w, p)
            written.append(p)
            book += _write_codebook(w, meaning, name)
            if phase.get("adaptive") and fmt != "spss":  # and its trials, one by one
                trials = _long([(design, phase, rows)])
                if fmt == "jasp":
                    trials.columns = [_safe(c) for c in trials.columns]
                name = f"trials_{_safe(design['protocol'])}_{_safe(phase['name'])}.csv"
                p = out / name
                _write_csv(trials, p)
                written.append(p)
                book += _write_codebook(trials, _long_entries(trials.columns, answers), name)
        if fmt == "spss":  # the trials too, for mixed models in SPSS
            long = _long(parts)
            long.columns = [_safe(c) for c in long.columns]
            entries = _long_entries(long.columns, answers)
            p = out / "long.sav"
            _write_sav(p, long, entries, labels)
            written.append(p)
            book += _write_codebook(long, entries, p.name)
    p = out / "codebook.csv"
    with p.open("w", newline="", encoding="utf-8") as fh:  # as load.py and load.R read it
        wr = csv.DictWriter(fh, fieldnames=["file", "column", "type", "unit", "meaning"])
        wr.writeheader()
        wr.writerows(book)
    written.append(p)
    return written


#: load.py, written beside the CSV files: pandas alone, no hapticlab needed
_PY_LOADER = '''"""Read this export's CSV files with pandas, each column as codebook.csv types it.

A participant id 001 stays the text "001" (pandas reads it as the number 1 unless told the
column is text). Run ``python -i load.py``, or from another script::

    tables = runpy.run_path("load.py")["tables"]   # file name -> DataFrame
"""

from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
book = pd.read_csv(HERE / "codebook.csv", dtype=str, keep_default_na=False)
tables = {}
for name, columns in book.groupby("file", sort=False):
    if not name.endswith(".csv"):
        continue
    text = list(columns.loc[columns["type"] == "text", "column"])
    header = pd.read_csv(HERE / name, nrows=0).columns
    tables[name] = pd.read_csv(HERE / name, dtype={c: str for c in text},
                               keep_default_na=False, na_values={c: [""] for c in header})
long = tables.get("long.csv")
'''


def _r_name(column: str) -> str:
    """The name R's read.csv gives ``column`` (``make.names``: ``grain-size`` is
    ``grain.size``, ``2nd`` is ``X2nd``)."""
    name = re.sub(r"[^0-9A-Za-z._]", ".", str(column))
    if not name or name[0].isdigit() or name[0] == "_" or re.match(r"\.[0-9]", name):
        name = "X" + name
    return name


def _r_script(long: pd.DataFrame, parts) -> str:
    levels: dict[str, list] = {"sample": []}
    for _design, phase, rows in parts:
        present = set(rows["sample"])
        levels["sample"] += [s for s in phase.get("samples", [])  # the protocol's order
                             if s in present and s not in levels["sample"]]
        levels["sample"] += sorted(present - set(levels["sample"]), key=str)
        for f in phase.get("within", []):
            if f in rows and f != "sample":
                levels.setdefault(f, ["low", "high"] if set(rows[f].dropna()) <= {"low", "high"}
                                  else sorted(set(rows[f].dropna()), key=str))
    lines = ["# Reads long.csv, written by: hapticlab export DATA --out DIR --format r",
             "# (codebook.csv gives the units).",
             "# Text columns are read as text: a participant id 001 stays 001.",
             'd <- read.csv("long.csv", stringsAsFactors = FALSE, na.strings = "",',
             "              colClasses = c(" + ", ".join(
                 f'"{_r_name(c)}" = "character"' for c in long.columns
                 if _type(long[c]) == "text") + "))",
             "d$participant <- factor(d$participant)"]
    for f, lv in levels.items():
        if f in long.columns:
            q = ", ".join(f'"{x}"' for x in lv)
            lines.append(f'd[["{_r_name(f)}"]] <- factor(d[["{_r_name(f)}"]], levels = c({q}))')
    lines += ["# rating is the dependent variable of the one-way analyses (ANOVA on participant",
              "# x sample means, t-tests, Wilcoxon, Friedman, lmer and clmm on the trials);",
              "# rating_z (z within participant, or participant and block, SD with divisor n)",
              "# is the factorial ANOVA's: afex::aov_ez(\"participant\", \"rating_z\",",
              "#   subset(d, block == \"wood\"), within = c(\"frequency\", \"decay\", \"slope\"))",
              "# reproduces the report's wood table. codebook.csv gives every column's unit."]
    return "\n".join(lines) + "\n"
