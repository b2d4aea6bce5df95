"""Session folders of a study of any size, written fast: what ``bench scale`` analyses and
what the tests of analysis at scale start from.

Running 21,700 simulated sessions would take hours; these folders are written directly in
the session format (:mod:`analysis.session_format`: session.json with the protocol's
recorded design, trials.tsv one row per attempt), with each participant's trials in the
order the session engine plans for a seed, and ratings drawn from a simple model (a mean
per sample or set, an offset per participant, trial noise; rounded and clipped to the
scale). Nothing is simulated on a device and no traces are written: the analysis reads
neither.

Everything comes from one ``numpy.random.Generator`` built from ``seed``.
"""

from __future__ import annotations

import datetime as dt
import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["write_study", "rows_per_participant"]

#: plans computed for this many seeds, taken in turn (the engine needs ~2 ms per plan)
_PLANS = 64


def _plans(protocol, seed: int) -> list[tuple[int, list, list]]:
    from protocols import SessionEngine

    out = []
    for k in range(_PLANS):
        s = seed * _PLANS + k
        e = SessionEngine(protocol, s, f"P{k}")
        out.append((s, e.plan(), e.placements()))
    return out


def rows_per_participant(protocol: str = "realism") -> float:
    """Mean rows per participant that :func:`write_study` writes for ``protocol`` (the
    planned trials, a reference tap per block, one redrawn attempt for every other
    participant)."""
    from protocols import load_protocol

    p = load_protocol(protocol)
    plan = _plans(p, 0)[0][1]
    blocks = {it.block for it in plan if it.block}
    return len(plan) + len(blocks) + 0.5


def _meta(protocol, design_json: str, pid: str, seed: int, created: str) -> str:
    meta = {"format_version": 3, "kind": "simulated", "responder": "simulated",
            "app": {"name": "hapticlab", "version": "0.1.0", "git_sha": ""},
            "audio": False, "libraries": {}, "link": {}, "timing": {}, "resumes": [],
            "device": {"backend": "sim", "firmware": "sim", "spec": "sim",
                       "model": "hapticlab simulated stylus device",
                       "serial_number": "SIM-study"},
            "participant": {"id": pid, "group": "", "counterbalance_row": None},
            "protocol": {"name": protocol.name, "sha256": protocol.sha256, "ref": protocol.name,
                         "copy": "protocol.toml", "design": "@DESIGN@"},
            "seed": seed, "session": 1, "status": "complete", "traces_mode": "none",
            "times": {"created_utc": created, "finished_utc": created}}
    return json.dumps(meta, indent=1).replace('"@DESIGN@"', design_json)


def write_study(out: str | Path, participants: int, protocol: str = "realism", seed: int = 0,
                prefix: str = "P", progress: Callable[[int, int], None] | None = None) -> dict:
    """Write ``participants`` complete sessions of ``protocol`` under ``out``
    (``sub-<prefix><k>/ses-1``).

    Parameters
    ----------
    out : path
        The data folder (created).
    participants : int
        How many (ids ``<prefix>00001`` …, as wide as the count needs).
    protocol : str
        A built-in protocol name or file; its rated phases get ratings.
    seed : int
        Every draw comes from ``numpy.random.default_rng(seed)``.
    prefix : str
        Participant id prefix.
    progress : callable (done, total), optional
        Called every 1000 participants and at the end.

    Returns
    -------
    dict
        ``participants``, ``rows`` (written), ``folder``.
    """
    from protocols import load_protocol, protocol_text

    p = load_protocol(protocol)
    design = p.design()
    design_json = json.dumps(design)
    scale = design.get("scale") or {"min": 1, "max": 7}
    lo, hi = scale["min"], scale["max"]
    rng = np.random.default_rng(seed)
    plans = _plans(p, seed)
    samples = sorted({s for _, plan, _ in plans for it in plan for s in it.samples})
    # a mean per sample or set across the scale, and factor effects where samples carry them
    centre = (lo + hi) / 2
    mean = dict(zip(samples, centre + rng.uniform(-0.3, 0.3, len(samples)) * (hi - lo),
                    strict=True))
    rated = {ph["name"] for ph in design["phases"] if ph.get("dv") == "rating"}
    info = design.get("samples", {})
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    width = max(5, len(str(participants)))
    text = protocol_text(protocol)[1]
    day0 = dt.datetime(2026, 1, 5, 9, tzinfo=dt.UTC)
    n_rows = 0
    for k in range(participants):
        pid = f"{prefix}{k + 1:0{width}d}"
        s, plan, places = plans[k % len(plans)]
        offset = rng.normal(0, 0.7)
        noise = rng.normal(0, 1.0, len(plan) + 1)
        created = (day0 + dt.timedelta(minutes=40 * k)).isoformat(timespec="milliseconds")
        lines = ["\t".join(("participant", "session", "phase", "trial_index", "item",
                            "attempt", "sample", "block", "factors", "placement", "status",
                            "n_taps", "tap_velocities", "peak_current", "rating",
                            "response_time", "answer", "correct", "reason", "t_start",
                            "t_end", "trace_file"))]
        redraw = k % 2 == 1  # every other participant saturates once and is redrawn
        seen_blocks: set[str] = set()
        trial = 0
        for i, (it, place) in enumerate(zip(plan, places, strict=True)):
            trial += 1
            sample = it.samples[0] if len(it.samples) == 1 else "+".join(it.samples)
            block = it.block or ""
            factors = ";".join(f"{f}={v}" for f, v in
                               (info.get(sample, {}).get("factors") or {}).items())
            if block and block not in seen_blocks:  # the real block, tapped for comparison
                seen_blocks.add(block)
                ref = next((n for n, v in info.items() if v.get("block") == block
                            and v.get("real")), f"{block}-real")
                lines.append(f"{pid}\t1\t{it.phase}\t{trial}\t{it.phase}/ref:{ref}\t0\t{ref}"
                             f"\t{block}\t\treal {block} block\treference\t5\t\t0\t\t\t\t\t"
                             f"\t\t\t")
            rating = ""
            if it.phase in rated:
                y = mean.get(sample, centre) + offset + noise[i]
                rating = str(int(min(hi, max(lo, round(y)))))
            taps = "0.11000;0.12000;0.10000"
            if redraw and it.phase in rated and i == len(plan) - 1:
                lines.append(f"{pid}\t1\t{it.phase}\t{trial}\t{it.key}\t1\t{sample}\t{block}"
                             f"\t{factors}\t{place or ''}\tsaturated\t3\t{taps}\t1.4\t\t\t\t\t"
                             "\t\t\t")
                trial += 1
                attempt = 2
            else:
                attempt = 1
            lines.append(f"{pid}\t1\t{it.phase}\t{trial}\t{it.key}\t{attempt}\t{sample}\t"
                         f"{block}\t{factors}\t{place or ''}\tvalid\t3\t{taps}\t0.6\t{rating}"
                         f"\t1.5\t\t\t\t\t\t")
        folder = out / f"sub-{pid}" / "ses-1"
        os.makedirs(folder, exist_ok=True)
        (folder / "trials.tsv").write_text("\n".join(lines) + "\n", encoding="utf-8")
        (folder / "session.json").write_text(_meta(p, design_json, pid, s, created),
                                             encoding="utf-8")
        (folder / "protocol.toml").write_text(text, encoding="utf-8")
        n_rows += len(lines) - 1
        if progress is not None and ((k + 1) % 1000 == 0 or k + 1 == participants):
            progress(k + 1, participants)
    return {"participants": participants, "rows": n_rows, "folder": str(out)}
