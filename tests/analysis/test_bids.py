"""The BIDS export (issue 32, items 3 and 4), checked by the official BIDS validator (the
Deno build from the package index, `bids-validator-deno`), run inside a private network
namespace with loopback alone where one can be made (nothing leaves this machine), on the
bundled study and on a messy one: participant ids BIDS does not allow that collide once
mapped, an interrupted session and a later complete one, full traces, contact snippets
and identification's three windows per trial."""

from __future__ import annotations

import gzip
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import analysis as A
from analysis.bids import export_bids

from ..app.test_session import MINI
from ..conftest import PRIVATE_NET, private_net_problem

pytestmark = [pytest.mark.integration]

CLI = [sys.executable, "-m", "app"]
VALIDATOR = Path(sys.executable).parent / "bids-validator-deno"


def _offline(cmd: list[str]) -> list[str]:
    """``cmd`` inside a new network namespace with loopback alone, where this machine lets
    one be made (tools/private_net.py); otherwise ``cmd`` as it is (the validator reads
    files and needs no network)."""
    return cmd if private_net_problem() else [*PRIVATE_NET, *cmd]


def validate(folder: Path) -> tuple[list[dict], list[dict]]:
    """(errors, warnings) the BIDS validator reports for ``folder``."""
    if not VALIDATOR.exists():
        pytest.fail(f"{VALIDATOR} is missing: `make test` installs bids-validator-deno")
    run = subprocess.run(_offline([str(VALIDATOR), str(folder), "--format", "json",
                                   "--max-rows", "-1"]),
                         capture_output=True, text=True, timeout=600)
    try:
        report = json.loads(run.stdout)
    except json.JSONDecodeError:
        pytest.fail(f"the validator printed no JSON (exit {run.returncode}): "
                    f"{run.stderr[-2000:]}")
    issues = report["issues"]["issues"]
    errors = [i for i in issues if i["severity"] == "error"]
    assert (run.returncode != 0) == bool(errors), run.stderr[-2000:]
    return errors, [i for i in issues if i["severity"] == "warning"]


#: the warnings a hapticlab export keeps, each for a reason the README gives
KEPT_WARNINGS = {"TOO_FEW_AUTHORS", "JSON_KEY_RECOMMENDED", "SIDECAR_KEY_RECOMMENDED"}


def test_the_bundled_study_is_a_valid_bids_dataset(tmp_path):
    out = tmp_path / "bids"
    res = export_bids(A.datasets.sessions_path(), out)
    errors, warnings = validate(out)
    assert not errors, json.dumps(errors, indent=1)[:3000]
    assert {w["code"] for w in warnings} <= KEPT_WARNINGS, {w["code"] for w in warnings}
    assert res["sessions"] == 3
    # every attempt of trials.tsv is a row, in its order, with its cells as recorded ('' is
    # n/a), and its onset is its recorded start less the session's creation time
    for sub in ("P01", "P02", "P03"):
        folder = A.datasets.sessions_path() / f"sub-{sub}" / "ses-1"
        src = pd.read_csv(folder / "trials.tsv", sep="\t", dtype=str, keep_default_na=False)
        (beh,) = (out / f"sub-{sub}" / "ses-1" / "beh").glob("*_beh.tsv")
        got = pd.read_csv(beh, sep="\t", dtype=str, keep_default_na=False)
        for col in ("item", "attempt", "status", "rating", "response_time", "tap_velocities",
                    "factors", "placement"):
            assert list(got[col]) == [v or "n/a" for v in src[col]], col
        (ev,) = (out / f"sub-{sub}" / "ses-1" / "beh").glob("*_events.tsv")
        created = pd.Timestamp(json.loads((folder / "session.json").read_text())["times"]
                               ["created_utc"])
        want = [(pd.Timestamp(t) - created).total_seconds() for t in src["t_start"]]
        assert np.allclose(pd.read_csv(ev, sep="\t")["onset"], want, atol=1e-3)
    side = json.loads(next(out.glob("task-*_beh.json")).read_text())
    assert side["rating"]["Levels"]["1"].startswith("1 on the 1–9 scale")
    assert sorted(side["rating"]["Levels"], key=int) == [str(k) for k in range(1, 10)]


@pytest.fixture(scope="module")
def messy(tmp_path_factory):
    """Sessions a real study leaves: ids with '_' and '-', traces in full and as contact
    snippets, a session cut short (interrupted) and the same person's complete session
    after it, and identification trials whose three windows are kept in full."""
    data = tmp_path_factory.mktemp("messy")
    proto = data / "mini.toml"
    proto.write_text(MINI)
    ident = data / "identify.toml"
    ident.write_text((Path(A.__file__).parents[1] / "protocols" / "identification.toml")
                     .read_text().replace("repetitions = 3", "repetitions = 1")
                     .replace('references = "start"', 'references = "none"'))
    runs = (("P_01", "full", proto), ("P-01", "contacts", proto), ("p01x", "full", proto),
            ("p01x", "full", proto), ("Q1", "full", ident))
    for pid, traces, p in runs:
        run = subprocess.run([*CLI, "run", str(p), "--participant", pid, "--seed", "3",
                              "--data", str(data), "--device", "sim", "--responder",
                              "scripted", "--no-audio", "--quiet", "--traces", traces,
                              "--new-session"],
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr
        if pid == "p01x" and not (data / "sub-p01x" / "ses-2").exists():
            # the first session ended early: its last rows cut, its status 'interrupted'
            folder = data / "sub-p01x" / "ses-1"
            lines = (folder / "trials.tsv").read_text().splitlines(keepends=True)
            (folder / "trials.tsv").write_text("".join(lines[:4]))
            meta = json.loads((folder / "session.json").read_text())
            meta["status"] = "interrupted"
            (folder / "session.json").write_text(json.dumps(meta))
    return data


@pytest.mark.slow
def test_a_messy_study_is_a_valid_bids_dataset_with_its_mapping_written(messy, tmp_path):
    out = tmp_path / "bids"
    res = export_bids(messy, out, kind="dry-run")
    errors, warnings = validate(out)
    assert not errors, json.dumps(errors, indent=1)[:3000]
    assert {w["code"] for w in warnings} <= KEPT_WARNINGS, {w["code"] for w in warnings}
    # labels: letters and digits, unique, stable (an id's label does not depend on the
    # others exported with it), and the ids as entered written beside them
    labels = res["labels"]
    assert labels["p01x"] == "p01x" and labels["Q1"] == "Q1"
    assert labels["P_01"] != labels["P-01"]
    assert all(re.fullmatch(r"[A-Za-z0-9]+", v) for v in labels.values())
    alone = export_bids(messy, tmp_path / "alone", kind="dry-run", participants=["P_01"])
    assert alone["labels"] == {"P_01": labels["P_01"]}
    people = pd.read_csv(out / "participants.tsv", sep="\t", dtype=str)
    assert dict(zip(people["hapticlab_id"], people["participant_id"], strict=True)) == {
        pid: f"sub-{label}" for pid, label in labels.items()}
    # every session of a participant, the interrupted one too
    visits = pd.read_csv(out / "sub-p01x" / "sub-p01x_sessions.tsv", sep="\t")
    assert list(visits["session_id"]) == ["ses-1", "ses-2"]
    assert list(visits["status"]) == ["interrupted", "complete"]
    # the contact snippets are not continuous: left out, and counted
    assert res["traces_left_out"] == 6 and res["traces_missing"] == 0
    assert not list((out / f"sub-{labels['P-01']}").rglob("*_physio.tsv.gz"))
    # an identification trial's three windows: three recordings, named in its row
    (beh,) = (out / "sub-Q1").rglob("*_beh.tsv")
    rows = pd.read_csv(beh, sep="\t", dtype=str)
    named = [r for r in rows["recording"] if r != "n/a"]
    assert named and all(len(r.split(";")) == 3 for r in named)
    for r in named:
        for label in r.split(";"):
            assert len(list((out / "sub-Q1").rglob(f"*_recording-{label}_physio.tsv.gz"))) == 1


def test_an_export_refuses_a_folder_in_use_and_an_empty_choice(messy, tmp_path):
    out = tmp_path / "bids"
    (out / "sub-old").mkdir(parents=True)
    with pytest.raises(A.LoadError, match="not empty"):
        export_bids(messy, out, kind="dry-run")
    with pytest.raises(A.LoadError, match="no session chosen"):
        export_bids(messy, tmp_path / "none", kind="dry-run", participants=["nobody"])


@pytest.mark.slow
def test_a_window_kept_in_full_is_a_physio_recording_in_si_units(messy, tmp_path):
    """Each full window: its samples at the device's rate, position = counts × the
    encoder's resolution and acceleration = counts × its LSB, the other streams as
    recorded (read here from the .npz directly)."""
    out = tmp_path / "bids"
    res = export_bids(messy, out, kind="dry-run")
    folder = messy / "sub-P_01" / "ses-1"
    rows = pd.read_csv(folder / "trials.tsv", sep="\t", dtype=str, keep_default_na=False)
    sub = res["labels"]["P_01"]
    physio = sorted((out / f"sub-{sub}").rglob("*_physio.tsv.gz"))
    assert len(physio) == len(rows) == 6
    for _k, row in rows.iterrows():
        trial = int(Path(row["trace_file"]).stem.split("-")[1])
        (p,) = [x for x in physio if f"_recording-t{trial:04d}w" in x.name]
        side = json.loads(p.with_name(p.name.replace(".tsv.gz", ".json")).read_text())
        with gzip.open(p, "rt") as fh:
            table = pd.read_csv(fh, sep="\t", header=None, names=side["Columns"])
        with np.load(folder / row["trace_file"]) as z:
            assert side["SamplingFrequency"] == float(z["rate_hz"])
            assert len(table) == len(z["position_counts"])
            pos = z["position_counts"] * float(z["encoder_resolution"])
            acc = z["accel_counts"] * float(z["accel_lsb"])
            for name in ("velocity", "force_cmd", "force_out", "current", "flags"):
                assert np.allclose(table[name], z[name], rtol=1e-7, atol=1e-12), name
        assert np.allclose(table["position"], pos, rtol=1e-8, atol=1e-12)
        assert np.allclose(table["accel"], acc, rtol=1e-8, atol=1e-9)
        assert side["position"] == {"Units": "m"} and side["accel"] == {"Units": "m/s^2"}


@pytest.mark.slow
def test_the_cli_writes_it_with_every_session(messy, tmp_path):
    """`hapticlab export --format bids`: interrupted sessions in by default (a raw dataset),
    out with --status complete."""
    def export(out, *extra):
        run = subprocess.run([*CLI, "export", str(messy), "--format", "bids", "--out",
                              str(out), "--kind", "dry-run", *extra],
                             capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        return pd.read_csv(out / "sub-p01x" / "sub-p01x_sessions.tsv", sep="\t")

    assert list(export(tmp_path / "all")["status"]) == ["interrupted", "complete"]
    assert list(export(tmp_path / "done", "--status", "complete")["status"]) == ["complete"]
    description = json.loads((tmp_path / "all" / "dataset_description.json").read_text())
    assert description["BIDSVersion"] == "1.10.0"
