"""The BIDS export (issue 32, items 3 and 4), checked by the official BIDS validator (the
Deno build from the package index, `bids-validator-deno`), run inside a private network
namespace with loopback alone where one can be made (nothing leaves this machine), on the
bundled study and on a messy one: participant ids BIDS does not allow that collide once
mapped, an interrupted session, a redrawn attempt, full traces and contact snippets."""

from __future__ import annotations

import gzip
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import analysis as A
from analysis.bids import bids_label, export_bids

from ..app.test_session import MINI

CLI = [sys.executable, "-m", "app"]
VALIDATOR = Path(sys.executable).parent / "bids-validator-deno"


def _offline(cmd: list[str]) -> list[str]:
    """``cmd`` inside a new network namespace with loopback alone, where this machine lets
    one be made (as root: unshare); otherwise ``cmd`` as it is (the validator reads files
    and needs no network)."""
    probe = subprocess.run(["unshare", "--net", "true"], capture_output=True)
    if shutil.which("unshare") is None or probe.returncode != 0:
        return cmd
    return ["unshare", "--net", "sh", "-c", 'ip link set lo up && exec "$@"', "sh", *cmd]


def validate(folder: Path) -> tuple[list[dict], list[dict]]:
    """(errors, warnings) the BIDS validator reports for ``folder``."""
    if not VALIDATOR.exists():
        pytest.fail(f"{VALIDATOR} is missing: `make test` installs bids-validator-deno")
    run = subprocess.run(_offline([str(VALIDATOR), str(folder), "--format", "json",
                                   "--max-rows", "-1"]),
                         capture_output=True, text=True, timeout=600)
    report = json.loads(run.stdout)
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
    # every attempt of trials.tsv is a row, in its order, with the same values
    for sub in ("P01", "P02", "P03"):
        src = pd.read_csv(A.datasets.sessions_path() / f"sub-{sub}" / "ses-1" / "trials.tsv",
                          sep="\t", dtype=str, keep_default_na=False)
        (beh,) = (out / f"sub-{sub}" / "ses-1" / "beh").glob("*_beh.tsv")
        got = pd.read_csv(beh, sep="\t", dtype=str, keep_default_na=False)
        assert list(got["item"]) == list(src["item"])
        assert list(got["rating"].replace("n/a", "")) == [
            "" if r == "" else f"{float(r):.1f}" for r in src["rating"]]
        (ev,) = (out / f"sub-{sub}" / "ses-1" / "beh").glob("*_events.tsv")
        onsets = pd.read_csv(ev, sep="\t")["onset"].to_numpy()
        assert np.all(np.diff(onsets) >= 0) and onsets[0] >= 0


@pytest.fixture(scope="module")
def messy(tmp_path_factory):
    """Sessions a real study leaves: ids with '_' and '-' that both map to P01, one with
    its traces in full and one with contact snippets, and one stopped by an e-stop."""
    data = tmp_path_factory.mktemp("messy")
    proto = data / "mini.toml"
    proto.write_text(MINI)
    for pid, traces in (("P_01", "full"), ("P-01", "contacts"), ("p01x", "full")):
        run = subprocess.run([*CLI, "run", str(proto), "--participant", pid, "--seed", "3",
                              "--data", str(data), "--device", "sim", "--responder",
                              "scripted", "--no-audio", "--quiet", "--traces", traces],
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr
    # a session that ended early: the last rows cut, its status 'interrupted'
    folder = data / "sub-p01x" / "ses-1"
    lines = (folder / "trials.tsv").read_text().splitlines(keepends=True)
    (folder / "trials.tsv").write_text("".join(lines[:4]))
    meta = json.loads((folder / "session.json").read_text())
    meta["status"] = "interrupted"
    (folder / "session.json").write_text(json.dumps(meta))
    return data


def test_a_messy_study_is_a_valid_bids_dataset_with_its_mapping_written(messy, tmp_path):
    out = tmp_path / "bids"
    res = export_bids(messy, out)
    errors, warnings = validate(out)
    assert not errors, json.dumps(errors, indent=1)[:3000]
    assert {w["code"] for w in warnings} <= KEPT_WARNINGS, {w["code"] for w in warnings}
    # labels: letters and digits, unique, and the ids as entered written beside them
    assert res["labels"] == {"P-01": "P01", "P_01": "P012", "p01x": "p01x"}
    people = pd.read_csv(out / "participants.tsv", sep="\t", dtype=str)
    assert dict(zip(people["hapticlab_id"], people["participant_id"], strict=True)) == {
        "P-01": "sub-P01", "P_01": "sub-P012", "p01x": "sub-p01x"}
    visits = pd.read_csv(out / "sub-p01x" / "sub-p01x_sessions.tsv", sep="\t")
    assert list(visits["status"]) == ["interrupted"]
    # the contact snippets are not continuous: left out, and counted
    assert res["traces_left_out"] == 6
    assert not list((out / "sub-P01").rglob("*_physio.tsv.gz"))


def test_a_window_kept_in_full_is_a_physio_recording_in_si_units(messy, tmp_path):
    """Each full window: its samples at the device's rate, position = counts × the
    encoder's resolution and acceleration = counts × its LSB (read here from the .npz
    directly), StartTime the attempt's onset."""
    out = tmp_path / "bids"
    export_bids(messy, out)
    folder = messy / "sub-P_01" / "ses-1"
    rows = pd.read_csv(folder / "trials.tsv", sep="\t", dtype=str, keep_default_na=False)
    events = pd.read_csv(next((out / "sub-P012").rglob("*_events.tsv")), sep="\t")
    physio = sorted((out / "sub-P012").rglob("*_physio.tsv.gz"))
    assert len(physio) == len(rows) == 6
    for k, row in rows.iterrows():
        rec = bids_label(Path(row["trace_file"]).stem)
        (p,) = [x for x in physio if f"_recording-{rec}_" in x.name]
        side = json.loads(p.with_name(p.name.replace(".tsv.gz", ".json")).read_text())
        with gzip.open(p, "rt") as fh:
            table = pd.read_csv(fh, sep="\t", header=None, names=side["Columns"])
        with np.load(folder / row["trace_file"]) as z:
            assert side["SamplingFrequency"] == float(z["rate_hz"])
            assert len(table) == len(z["position_counts"])
            pos = z["position_counts"] * float(z["encoder_resolution"])
            acc = z["accel_counts"] * float(z["accel_lsb"])
        assert np.allclose(table["position"], pos, rtol=1e-8, atol=1e-12)
        assert np.allclose(table["accel"], acc, rtol=1e-8, atol=1e-9)
        assert side["position"] == {"Units": "m"} and side["accel"] == {"Units": "m/s^2"}
        assert side["StartTime"] == pytest.approx(events["onset"].iloc[k], abs=1e-3)


def test_the_cli_writes_it(tmp_path):
    out = tmp_path / "bids"
    run = subprocess.run([*CLI, "export", str(A.datasets.sessions_path()), "--format", "bids",
                          "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert (out / "dataset_description.json").exists()
    assert json.loads((out / "dataset_description.json").read_text())["BIDSVersion"] == "1.10.0"
