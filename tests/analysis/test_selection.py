"""What is pooled is chosen and shown: a data folder mixing people's sessions, a dry run,
simulated sessions, an interrupted session, a reused participant id and a backup copy."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from analysis import load_sessions, select_sessions
from app.api import run_session, simulate_study

CLI = [sys.executable, "-m", "app"]
PROTO = str(Path(__file__).resolve().parents[1] / "data" / "protocols" / "six_on_nine.toml")


def _as_person(folder: Path, status: str = "complete") -> None:
    """Stand-in for a person's session: the file format a PsychoPy session writes (kind human,
    responder person, the lab's serial device); the ratings came from a scripted responder."""
    meta = json.loads((folder / "session.json").read_text())
    meta.update(kind="human", responder="person", ui="psychopy", status=status)
    meta["device"].update(backend="serial", model="hapticlab stylus", serial_number="HL-0042",
                          firmware="1.3", simulated_contact=False, seeded=False,
                          virtual_time=False)  # what the lab's device says of itself
    (folder / "session.json").write_text(json.dumps(meta))


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    data = tmp_path_factory.mktemp("mixed") / "data"
    for pid, seed in (("P01", 1), ("P02", 2), ("P01", 3), ("P03", 4), ("D01", 5)):
        r = run_session(PROTO, pid, device="sim", data=data, responder="scripted", seed=seed,
                        audio=False, quiet=True, traces="none")
        assert r.status == "complete"
    _as_person(data / "sub-P01" / "ses-1")
    _as_person(data / "sub-P02" / "ses-1")
    _as_person(data / "sub-P01" / "ses-2")  # the same participant id used again
    _as_person(data / "sub-P03" / "ses-1", status="interrupted")
    assert simulate_study(PROTO, 2, seed=7, data=data, prefix="S", traces="none",
                          progress=None).complete
    backup = data / "backup" / "sub-P02"
    shutil.copytree(data / "sub-P02", backup)  # a backup copy left in the folder
    return data


def _table(data):
    return load_sessions(data).attrs["session_table"]


@pytest.mark.integration  # the sessions record their provenance: git, uname
def test_default_is_people_only_with_every_exclusion_named(mixed):
    d = load_sessions(mixed)
    assert d.attrs["sessions"] == 8
    sel, table = select_sessions(d)
    got = {(Path(r.session_dir).relative_to(mixed).as_posix(), r.included): r.reason
           for r in table.itertuples()}
    inc = {k[0] for k in got if k[1]}
    assert inc == {"sub-P01/ses-1", "sub-P02/ses-1"}
    reasons = {k[0]: v for k, v in got.items()}
    assert "later session of P01" in reasons["sub-P01/ses-2"]
    assert "first complete session" in reasons["sub-P01/ses-2"]
    assert reasons["sub-P03/ses-1"].startswith("status interrupted")
    assert reasons["sub-D01/ses-1"] == "dry-run session (selected: human)"
    assert reasons["sub-S01/ses-1"] == "simulated session (selected: human)"
    assert reasons["backup/sub-P02/ses-1"].startswith("duplicate of ")
    assert reasons["sub-P01/ses-1"] == "kind human (the default: people's sessions exist)"
    assert set(sel["participant"]) == {"P01", "P02"}


@pytest.mark.integration  # the sessions record their provenance: git, uname
def test_first_session_means_the_first_complete_one(mixed, tmp_path):
    """With --status all, a participant whose first session was interrupted and who then
    completed a second is analysed on the complete one (it once kept the interrupted)."""
    data = tmp_path / "data"
    shutil.copytree(mixed, data)
    _as_person(data / "sub-P01" / "ses-1", status="interrupted")
    sel, table = select_sessions(load_sessions(data), status="all")
    got = {Path(r.session_dir).relative_to(data).as_posix(): (r.included, r.reason)
           for r in table.itertuples()}
    assert got["sub-P01/ses-2"][0] and not got["sub-P01/ses-1"][0]
    assert got["sub-P01/ses-1"][1].startswith("an earlier interrupted session of P01")
    assert "first complete session" in got["sub-P01/ses-1"][1]
    kept = {Path(x).name for x in sel.loc[sel["participant"] == "P01", "session_dir"]}
    assert kept == {"ses-2"}


@pytest.mark.integration
def test_a_folder_renamed_to_another_participant_is_named_not_merged(mixed, tmp_path):
    """P03's session moved into sub-P09 (a wrong --participant, then a renamed folder): it
    was once merged silently with whichever participant the files named. Now it is left
    out and named; --ids record or folder decides."""
    data = tmp_path / "data"
    shutil.copytree(mixed, data)
    _as_person(data / "sub-P03" / "ses-1")
    (data / "sub-P03").rename(data / "sub-P09")
    d = load_sessions(data)
    sel, table = select_sessions(d)
    row = table[table["session_dir"].str.contains("sub-P09")].iloc[0]
    assert not row.included
    assert row.reason.startswith("folder sub-P09 holds participant P03's session")
    assert "--ids record" in row.reason and "--ids folder" in row.reason
    sel, _ = select_sessions(d, ids="record")
    assert "P03" in set(sel["participant"])
    sel, _ = select_sessions(d, ids="folder")
    assert "P09" in set(sel["participant"]) and "P03" not in set(sel["participant"])
    out = subprocess.run([*CLI, "analyze", str(data), "--out", str(tmp_path / "r"),
                          "--ids", "folder", "--format", "json"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr


@pytest.mark.integration  # the sessions record their provenance: git, uname
def test_filters(mixed):
    d = load_sessions(mixed)
    sim, _ = select_sessions(d, kind="simulated")
    assert set(sim["participant"]) == {"S01", "S02"}
    every, t = select_sessions(d, status="all")
    assert "P03" in set(every["participant"])
    one, _ = select_sessions(d, participants=["P02"])
    assert set(one["participant"]) == {"P02"}
    none, t = select_sessions(d, since="2999-01-01")
    assert none.empty and not t["included"].any()
    assert all("before --since" in r for r in t["reason"] if "session (selected" not in r
               and "status" not in r and "duplicate" not in r and "later" not in r)
    _, t = select_sessions(d, protocol="realism")
    assert not t["included"].any() and set(t["reason"]) == {"protocol six_on_nine not selected"}


@pytest.mark.integration
@pytest.mark.slow
def test_cli_report_opens_with_the_selection(mixed, tmp_path):
    out = subprocess.run([*CLI, "analyze", str(mixed), "--out", str(tmp_path / "r"),
                          "--format", "json,md,html"], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert "1 analyses (six_on_nine/main) of 2 sessions (6 excluded" in out.stdout
    assert "human sessions" in out.stdout
    rep = json.loads((tmp_path / "r" / "report.json").read_text())
    assert rep["selection"]["included"] == 2 and rep["selection"]["excluded"] == 6
    assert rep["analyses"][0]["n_subjects"] == 2
    md = (tmp_path / "r" / "report.md").read_text()
    first = md.index("## Sessions included and excluded")
    assert first < md.index("## six_on_nine/main")
    assert ("| P03 | 1 | six_on_nine | human | serial | hapticlab stylus #HL-0042 | 1.3 | "
            "interrupted |") in md
    assert "2 of 8 sessions included (kind: human, status: complete)" in rep["methods"]
    # another selection, chosen on the command line
    sim = subprocess.run([*CLI, "analyze", str(mixed), "--out", str(tmp_path / "s"),
                          "--format", "json", "--kind", "simulated"], capture_output=True,
                         text=True, timeout=300)
    assert sim.returncode == 0, sim.stderr
    srep = json.loads((tmp_path / "s" / "report.json").read_text())
    assert srep["methods"].startswith("These data come from simulated participants")
    nothing = subprocess.run([*CLI, "analyze", str(mixed), "--out", str(tmp_path / "n"),
                              "--since", "2999-01-01"], capture_output=True, text=True,
                             timeout=300)
    assert nothing.returncode == 1 and "nothing was analysed" in nothing.stderr
    bad = subprocess.run([*CLI, "analyze", str(mixed), "--out", str(tmp_path / "b"),
                          "--since", "yesterday"], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "--since" in bad.stderr and "Traceback" not in bad.stderr


@pytest.mark.integration
@pytest.mark.slow
def test_simulate_writes_to_its_own_folder(tmp_path):
    out = subprocess.run([*CLI, "simulate", PROTO, "--participants", "1", "--traces", "none"],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "sim-data" / "sub-sim01" / "ses-1" / "session.json").exists()
    assert not (tmp_path / "data").exists()


@pytest.mark.integration
def test_a_person_needs_a_device_and_a_dry_run_says_so(tmp_path):
    out = subprocess.run([*CLI, "run", PROTO, "--participant", "P09", "--data", str(tmp_path)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "needs --device" in out.stderr and "--dry-run" in out.stderr
    assert not any(tmp_path.iterdir())
    dry = subprocess.run([*CLI, "run", PROTO, "--participant", "P09", "--data", str(tmp_path),
                          "--dry-run", "--no-audio", "--quiet"], capture_output=True, text=True,
                         timeout=120)
    assert dry.returncode == 0, dry.stderr
    meta = json.loads((tmp_path / "sub-P09" / "ses-1" / "session.json").read_text())
    assert meta["kind"] == "dry-run" and meta["responder"] == "scripted"
    assert meta["protocol"]["design"]["phases"][1]["within"] == ["sample"]
