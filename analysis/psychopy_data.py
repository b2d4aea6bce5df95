"""A PsychoPy experiment's data (its CSV files, as the psychopy-hapticlab components write
them) read into hapticlab's long format, where the experiment's design is one hapticlab
analyses.

A PsychoPy experiment records no design: which columns hold the samples felt and the answer
is said here by the analyst. Two designs fit:

- ``comparison``: a two-alternative forced choice between two samples felt one after the
  other (the plugin's demo), analysed as hapticlab's paired comparisons
  (:func:`analysis.study.choice_scores`);
- ``oneway``: ratings of samples, analysed as hapticlab's one-way repeated-measures design
  (:func:`analysis.study.rating_oneway`).

The others do not, and :func:`load_psychopy` says why by name (:data:`WHY_NOT`). Reads files
only; imports no PsychoPy.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from .load import LoadError

__all__ = ["DESIGNS", "WHY_NOT", "load_psychopy", "analyse_psychopy"]

#: the designs a PsychoPy experiment's data can be analysed as, and the phase design each
#: stands for (what a hapticlab protocol records)
DESIGNS = {"comparison": {"dv": "choice"}, "oneway": {"dv": "rating", "within": ["sample"]}}

#: hapticlab's other analyses, and why a PsychoPy experiment's data cannot have them
WHY_NOT = {
    "factorial": "the factorial analysis z-scores ratings per subject within each material "
                 "block and tests the crossed factors a protocol declares per sample; a "
                 "PsychoPy experiment records neither the factors of its scenes nor its "
                 "blocks (run it as hapticlab's factorial protocol)",
    "identification": "the identification test scores a scene of several surfaces named "
                      "together against the materials rendered on each; a Haptic contact "
                      "renders one surface a window and its row holds no surface-to-material "
                      "map (run it as hapticlab's identification protocol)",
}


def _read(paths) -> pd.DataFrame:
    if isinstance(paths, (str, Path)):
        paths = [paths]
    frames = []
    for p in paths:
        p = Path(p)
        files = sorted(p.glob("*.csv")) if p.is_dir() else [p]
        for f in files:
            try:
                d = pd.read_csv(f)
            except (OSError, pd.errors.ParserError, UnicodeDecodeError) as exc:
                raise LoadError(f"{f}: cannot be read as a PsychoPy data file ({exc})") \
                    from None
            d["data_file"] = str(f)
            d["row"] = np.arange(len(d))
            frames.append(d)
    if not frames:
        raise LoadError(f"no PsychoPy data files (*.csv) in {', '.join(map(str, paths))}")
    return pd.concat(frames, ignore_index=True)


def _need(d: pd.DataFrame, cols: Iterable[str], design: str) -> None:
    missing = [c for c in cols if c not in d.columns]
    if missing:
        raise LoadError(f"a {design} design needs the column(s) {', '.join(missing)}; the data "
                        f"have {', '.join(c for c in d.columns if not c.startswith('Unnamed'))}")


def _speeds(v) -> list[float]:
    if not isinstance(v, str) or not v.strip("[] "):
        return []
    return [float(x) for x in v.strip("[]").split(",") if x.strip() not in ("", "None")]


def load_psychopy(paths, design: str, *, taps: Iterable[str] = ("tap_first", "tap_second"),
                  subject: str = "participant", first: str = "first", second: str = "second",
                  choice: str = "choice.keys", keys: tuple = ("1", "2"),
                  sample: str = "sample", rating: str = "rating") -> pd.DataFrame:
    """Trials of PsychoPy data files in hapticlab's long format, one row per trial.

    Parameters
    ----------
    paths : path or list of paths
        CSV files, or folders of them (one per participant and session, as PsychoPy writes).
    design : str
        ``comparison`` or ``oneway`` (:data:`DESIGNS`).
    taps : list of str
        The Haptic contact components of a trial (their ``<name>.status`` and
        ``<name>.speeds`` columns): a trial is valid when every one of them is.
    subject : str
        The participant column (PsychoPy's experiment info).
    first, second, choice, keys
        ``comparison``: the columns naming the samples felt first and second, the key
        pressed, and the keys meaning "the first" and "the second".
    sample, rating
        ``oneway``: the columns naming the sample and holding its rating.

    Returns
    -------
    DataFrame
        ``participant``, ``trial_index``, ``sample`` (``first+second`` for a comparison),
        ``answer`` (the sample chosen) or ``rating``, ``status`` (``valid``, the first tap's
        status that is not, or ``no_response``), ``valid``, ``n_taps``,
        ``tap_velocities`` (``;``-joined, m/s), ``data_file``, ``row``.

    Raises
    ------
    LoadError
        A design hapticlab cannot analyse from such data (named, with why), a missing
        column, or a file that cannot be read.
    """
    if design in WHY_NOT:
        raise LoadError(f"a PsychoPy experiment's data cannot be analysed as {design}: "
                        f"{WHY_NOT[design]}")
    if design not in DESIGNS:
        raise LoadError(f"unknown design {design!r}; PsychoPy data are analysed as "
                        f"{' or '.join(DESIGNS)}")
    taps = list(taps)
    d = _read(paths)
    cols = [subject, *(f"{t}.{c}" for t in taps for c in ("status", "speeds"))]
    cols += [first, second, choice] if design == "comparison" else [sample, rating]
    _need(d, cols, design)
    d = d[d[f"{taps[0]}.status"].notna()].copy() if taps else d
    if d.empty:
        raise LoadError(f"no trial rows: no row has {taps[0]}.status")
    status = pd.Series("valid", index=d.index)
    for t in reversed(taps):
        s = d[f"{t}.status"].astype(str)
        status = status.where(s == "valid", s)
    speeds = d.apply(lambda r: [v for t in taps for v in _speeds(r[f"{t}.speeds"])], axis=1)
    out = pd.DataFrame({"participant": d[subject].astype(str).to_numpy(),
                        "trial_index": d["row"].to_numpy(),
                        "data_file": d["data_file"].to_numpy(), "row": d["row"].to_numpy()})
    if design == "comparison":
        key = d[choice].map(lambda k: "" if pd.isna(k) else str(k).strip("[]' ").removesuffix(
            ".0"))
        if not key[key != ""].isin([str(k) for k in keys]).all():
            bad = sorted(set(key[(key != "") & ~key.isin([str(k) for k in keys])]))
            raise LoadError(f"{choice}: keys {', '.join(bad)} are neither {keys[0]} (the first) "
                            f"nor {keys[1]} (the second)")
        out["sample"] = (d[first].astype(str) + "+" + d[second].astype(str)).to_numpy()
        out["answer"] = np.where(key == str(keys[0]), d[first].astype(str),
                                 np.where(key == str(keys[1]), d[second].astype(str), ""))
        status = status.where(key != "", "no_response")
    else:
        r = pd.to_numeric(d[rating], errors="coerce")
        out["sample"] = d[sample].astype(str).to_numpy()
        out["rating"] = r.to_numpy()
        status = status.where(r.notna(), "no_response")
    out["status"] = status.to_numpy()
    out["valid"] = out["status"] == "valid"
    out["n_taps"] = speeds.map(len).to_numpy()
    out["tap_velocities"] = speeds.map(lambda v: ";".join(f"{x:.5f}" for x in v)).to_numpy()
    return out


def analyse_psychopy(data: pd.DataFrame, design: str, alpha: float = 0.05) -> dict:
    """hapticlab's analysis of :func:`load_psychopy`'s trials for ``design``: what
    :func:`analysis.analyses.analyse_phase` returns (``type``, ``result``, ``device``)."""
    from .analyses import analyse_phase

    if design not in DESIGNS:
        raise LoadError(f"unknown design {design!r}; PsychoPy data are analysed as "
                        f"{' or '.join(DESIGNS)}")
    return analyse_phase(data, {"name": design, **DESIGNS[design]}, alpha)
