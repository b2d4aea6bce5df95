"""`hapticlab resume` on hostile session folders (issue 53, items 5 and 6): a status the
recorder never writes, and files that are links out of the session folder, are refused by
name before anything is written — and nothing outside the folder is touched."""

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration]

CLI = [sys.executable, "-m", "app"]
MINI = Path(__file__).resolve().parents[1] / "data" / "mini.toml"


def run(*args, **kw):
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600, **kw)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A complete session of the mini protocol (6 attempts, no traces)."""
    data = tmp_path_factory.mktemp("data")
    out = run("run", str(MINI), "--participant", "P04", "--seed", "2", "--data", str(data),
              "--dry-run", "--no-audio", "--quiet", "--traces", "none")
    assert out.returncode == 0, out.stderr
    return data / "sub-P04" / "ses-1"


def _interrupted(recorded: Path, where: Path, keep: int = 2) -> Path:
    """A copy of the session stopped after ``keep`` attempts."""
    folder = where / "sub-P04" / "ses-1"
    shutil.copytree(recorded, folder)
    lines = (folder / "trials.tsv").read_text().splitlines(keepends=True)
    (folder / "trials.tsv").write_text("".join(lines[: 1 + keep]))
    meta = json.loads((folder / "session.json").read_text())
    meta["status"] = "interrupted"
    (folder / "session.json").write_text(json.dumps(meta))
    return folder


def _digest(folder: Path) -> dict:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and not p.is_symlink()}


def test_a_capitalised_status_is_refused_naming_file_line_and_statuses(recorded, tmp_path):
    folder = _interrupted(recorded, tmp_path)
    t = folder / "trials.tsv"
    t.write_text(t.read_text().replace("\tvalid\t", "\tVALID\t", 1))
    before = _digest(folder)
    out = run("resume", str(folder))
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert f"{t}:2: status 'VALID' is not one of valid, saturated" in out.stderr
    assert "the recorder writes 'valid'" in out.stderr
    after = _digest(folder)
    after.pop("session.lock", None)
    before.pop("session.lock", None)
    assert after == before  # refused before anything was written


def test_trials_linked_out_of_the_folder_are_neither_read_nor_appended_to(recorded,
                                                                          tmp_path):
    folder = _interrupted(recorded, tmp_path / "d")
    outside = tmp_path / "elsewhere.tsv"
    shutil.move(folder / "trials.tsv", outside)
    (folder / "trials.tsv").symlink_to(outside)
    kept = outside.read_bytes()
    out = run("resume", str(folder))
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert f"{folder / 'trials.tsv'}: is a link to {outside}" in out.stderr
    assert "outside the session folder" in out.stderr
    assert outside.read_bytes() == kept  # 26 rows were appended here before


@pytest.mark.parametrize("name", ["session.json", "protocol.toml", "session.lock", "traces"])
def test_no_file_of_the_session_is_used_through_a_link_out_of_it(recorded, tmp_path, name):
    folder = _interrupted(recorded, tmp_path / "d")
    outside = tmp_path / f"outside-{name}"
    if (folder / name).exists():
        shutil.move(folder / name, outside)
    else:  # the lock: a file of someone else's that opening it would truncate
        outside.write_text("someone else's file\n")
    (folder / name).symlink_to(outside)
    kept = _digest(tmp_path / "d") if outside.is_dir() else outside.read_bytes()
    out = run("resume", str(folder))
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert f"{folder / name}: is a link to {outside}" in out.stderr
    if outside.is_dir():
        assert not any(outside.iterdir())
    else:
        assert outside.read_bytes() == kept


@pytest.mark.slow
def test_a_hard_linked_trials_file_gets_its_own_copy_before_rows_are_appended(recorded,
                                                                                tmp_path):
    """A backup made with hard links (``cp -al``, rsnapshot) shares trials.tsv with the
    session: appending to it would change the backup too."""
    folder = _interrupted(recorded, tmp_path / "d")
    backup = tmp_path / "backup-trials.tsv"
    os.link(folder / "trials.tsv", backup)
    kept = backup.read_bytes()
    out = run("resume", str(folder))
    assert out.returncode == 0, out.stderr
    assert "shared with another name" in out.stderr
    assert backup.read_bytes() == kept
    assert len((folder / "trials.tsv").read_text().splitlines()) == 7  # header + 6
