"""Sessions on test day: run, record, crash, resume."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from app.recorder import COLUMNS, SessionFiles, TrialsFileError, read_trials
from benchmarks.crash import kill_and_resume

CLI = [sys.executable, "-m", "app"]
HEADLESS = ["--dry-run", "--no-audio",
            "--quiet"]

MINI = (Path(__file__).resolve().parents[1] / "data" / "mini.toml").read_text()


def run(*args, **kw):
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600, **kw)


@pytest.fixture(scope="module")
def realism_session(tmp_path_factory):
    data = tmp_path_factory.mktemp("data")
    out = run("run", "realism", "--participant", "P01", "--seed", "1", "--data", str(data),
              *HEADLESS)
    assert out.returncode == 0, out.stderr
    return data / "sub-P01" / "ses-1"


@pytest.mark.integration
@pytest.mark.slow
def test_realism_session_files_and_counts(realism_session):
    files = SessionFiles(realism_session)
    assert (realism_session / "traces").is_dir()
    rows, torn = read_trials(files.trials)
    assert torn is None
    valid = [r for r in rows if r["status"] == "valid"]
    by_phase = {p: [r for r in valid if r["phase"] == p] for p in ("demonstration", "testing")}
    assert len(by_phase["demonstration"]) == 11 and len(by_phase["testing"]) == 33
    assert {r["sample"] for r in by_phase["demonstration"]} == {r["sample"]
                                                                 for r in by_phase["testing"]}
    assert all(1 <= int(r["rating"]) <= 7 for r in valid if r["phase"] != "familiarization")
    redraws = [r for r in rows if r["status"] in ("saturated", "excluded_saturated")]
    assert len(rows) == 45 + len(redraws)
    for r in rows:
        assert set(r) == set(COLUMNS)
        if r["trace_file"]:
            assert (realism_session / r["trace_file"]).exists()
    meta = json.loads(files.meta.read_text())
    assert meta["status"] == "complete" and meta["seed"] == 1
    assert meta["protocol"]["sha256"] and meta["app"]["git_sha"]
    assert meta["device"]["current_limit"] == 1.4 and meta["packages"]["numpy"]
    assert meta["times"]["created_utc"] and meta["times"]["finished_utc"]


@pytest.mark.integration
def test_placements_never_reveal_and_always_swap(realism_session):
    rows, _ = read_trials(realism_session / "trials.tsv")
    for r in rows:
        if r["sample"] in ("wood", "wood_on_foam", "foam"):
            assert r["placement"] == r["sample"]
        else:
            assert r["placement"] in ("placeholder A", "placeholder B")


@pytest.mark.integration
@pytest.mark.slow
def test_an_existing_session_is_never_overwritten(tmp_path):
    for n in (1, 2):
        out = run("run", "identification", "--participant", "P02", "--seed", "3", "--data",
                  str(tmp_path), *HEADLESS)
        assert out.returncode == 0, out.stderr
        assert (tmp_path / "sub-P02" / f"ses-{n}" / "trials.tsv").exists()


@pytest.mark.integration
def test_seed_is_drawn_and_recorded_when_not_given(tmp_path):
    out = run("run", "identification", "--participant", "P03", "--data", str(tmp_path),
              *HEADLESS)
    assert out.returncode == 0
    meta = json.loads((tmp_path / "sub-P03" / "ses-1" / "session.json").read_text())
    assert isinstance(meta["seed"], int) and meta["seed"] >= 0


@pytest.mark.integration
@pytest.mark.parametrize("pid, fragment", [
    ("../x", "path separator"), ("a/b", "path separator"), ("P..1", "'..'"),
    ("CON", "reserved device name"), ("nul", "reserved device name"),
    ("P\x0701", "control characters"), ("", "empty"), ("P 01", "use letters"),
    ("x" * 40, "longer than 32"),
    ("nan", "missing value"), ("NA", "missing value"), ("True", "truth value"),
])
def test_bad_participant_ids(tmp_path, pid, fragment):
    out = run("run", "realism", "--participant", pid, "--data", str(tmp_path), *HEADLESS)
    assert out.returncode == 2
    assert fragment in out.stderr and "Traceback" not in out.stderr
    assert not any(tmp_path.iterdir())


def _copy_session(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src.parent.parent, dst)
    return dst / src.parent.name / src.name


@pytest.mark.integration
@pytest.mark.slow
def test_torn_last_line_is_set_aside_and_the_attempt_rerun(realism_session, tmp_path):
    folder = _copy_session(realism_session, tmp_path / "d")
    lines = (folder / "trials.tsv").read_text().splitlines(keepends=True)
    full = "".join(lines)
    # as if killed while writing row 20: keep 19 rows and half of the 20th
    (folder / "trials.tsv").write_text("".join(lines[:20]) + lines[20][:30])
    meta = json.loads((folder / "session.json").read_text())
    meta["status"] = "interrupted"
    (folder / "session.json").write_text(json.dumps(meta))
    out = run("resume", str(folder))
    assert out.returncode == 0, out.stderr
    assert "torn last line" in out.stderr and "line 21" in out.stderr
    assert (folder / "trials.torn.tsv").read_text().strip() == lines[20][:30].strip()
    # the resumed session equals the uninterrupted one
    strip = lambda text: [ln.split("\t")[:15] for ln in text.splitlines()]  # noqa: E731
    assert strip((folder / "trials.tsv").read_text()) == strip(full)


@pytest.mark.integration
def test_a_corrupt_earlier_line_is_a_named_error(realism_session, tmp_path):
    folder = _copy_session(realism_session, tmp_path / "d")
    lines = (folder / "trials.tsv").read_text().splitlines(keepends=True)
    lines[5] = "garbage\tline\n"
    (folder / "trials.tsv").write_text("".join(lines))
    with pytest.raises(TrialsFileError, match=r"trials.tsv:6: corrupt line"):
        read_trials(folder / "trials.tsv")
    meta = json.loads((folder / "session.json").read_text())
    meta["status"] = "interrupted"
    (folder / "session.json").write_text(json.dumps(meta))
    out = run("resume", str(folder))
    assert out.returncode == 2 and "trials.tsv:6: corrupt line" in out.stderr


@pytest.mark.integration
@pytest.mark.slow
def test_resume_uses_the_sessions_protocol_copy_and_refuses_an_edited_one(tmp_path):
    proto = tmp_path / "mini.toml"
    proto.write_text(MINI)
    out = run("run", str(proto), "--participant", "P04", "--seed", "2", "--data",
              str(tmp_path / "d"), *HEADLESS)
    assert out.returncode == 0
    folder = tmp_path / "d" / "sub-P04" / "ses-1"
    assert (folder / "protocol.toml").read_text() == MINI  # the protocol travels with it
    rows = (folder / "trials.tsv").read_text().splitlines(keepends=True)
    (folder / "trials.tsv").write_text("".join(rows[:3]))  # as if stopped after 2 attempts
    meta = json.loads((folder / "session.json").read_text())
    meta["status"] = "interrupted"
    (folder / "session.json").write_text(json.dumps(meta))
    # the lab edits (or deletes) its file: the session keeps running its own copy, from
    # any working directory
    proto.write_text(MINI.replace("repetitions = 2", "repetitions = 3") + "# a comment\n")
    out = run("resume", str(folder), cwd=tmp_path / "d")
    assert out.returncode == 0, out.stderr
    strip = lambda text: [ln.split("\t")[:15] for ln in text.splitlines()]  # noqa: E731
    assert strip((folder / "trials.tsv").read_text()) == strip("".join(rows))  # as uninterrupted
    # the copy itself edited: refused, naming the file
    meta["status"] = "interrupted"
    (folder / "session.json").write_text(json.dumps(meta))
    (folder / "protocol.toml").write_text(MINI.replace("repetitions = 2", "repetitions = 3"))
    out = run("resume", str(folder))
    assert out.returncode == 2 and "changed since the session started" in out.stderr
    assert "protocol.toml" in out.stderr


@pytest.mark.integration
@pytest.mark.slow
def test_kill_harness_loses_nothing_and_resumes_exactly(tmp_path):
    """≥ 30 kill -9 at random moments (1000 in `hapticlab bench crash`), some of them, on a
    loaded machine, before the session is declared (the harness then follows the session
    the next run makes)."""
    r = kill_and_resume(30, workdir=tmp_path)
    assert r["kills"] == 30
    assert r["lost_rows_events"] == 0
    assert r["sequence_matches"], r["mismatched"]


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_headless_session_over_the_emulator(emulator, tmp_path):
    proto = tmp_path / "mini.toml"
    proto.write_text(MINI)
    out = run("run", str(proto), "--participant", "P05", "--seed", "4", "--data", str(tmp_path),
              "--device", f"serial:{emulator.port}", "--responder", "scripted", "--no-audio",
              "--quiet")
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "sub-P05" / "ses-1"
    rows, _ = read_trials(folder / "trials.tsv")
    assert sum(r["status"] == "valid" for r in rows) == 6
    meta = json.loads((folder / "session.json").read_text())
    assert meta["device"]["backend"] == "serial"
    assert meta["link"]["frames_sent"] > 0 and meta["link"]["crc_errors"] == 0


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_emulator_dies_mid_session_then_resume_on_a_new_one(tmp_path, emulator_factory):
    proto = tmp_path / "mini.toml"
    proto.write_text(MINI.replace("duration = 1.0", "duration = 2.0"))
    emu = emulator_factory(8)
    proc = subprocess.Popen([*CLI, "run", str(proto), "--participant", "P06", "--seed", "5",
                             "--data", str(tmp_path), "--device", f"serial:{emu.port}",
                             "--responder", "scripted", "--no-audio"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    folder = tmp_path / "sub-P06" / "ses-1"
    import time

    end = time.monotonic() + 60
    while time.monotonic() < end:  # wait until two trials are recorded, then pull the plug
        if (folder / "trials.tsv").exists() and len(read_trials(folder / "trials.tsv")[0]) >= 2:
            break
        time.sleep(0.1)
    emu.proc.kill()
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 3, err
    assert "resume with: hapticlab resume" in err
    rows, _ = read_trials(folder / "trials.tsv")
    assert rows[-1]["status"] == "aborted_device" and "device gone" in rows[-1]["reason"]
    assert json.loads((folder / "session.json").read_text())["status"] == "interrupted"
    emu2 = emulator_factory(9)
    out = run("resume", str(folder), "--device", f"serial:{emu2.port}", "--quiet")
    assert out.returncode == 0, out.stderr
    rows, _ = read_trials(folder / "trials.tsv")
    assert sum(r["status"] == "valid" for r in rows) == 6
    aborted = [r for r in rows if r["status"] == "aborted_device"]
    retried = [r for r in rows if r["item"] == aborted[0]["item"] and r["status"] == "valid"]
    assert retried and int(retried[0]["attempt"]) == int(aborted[0]["attempt"]) + 1


@pytest.mark.realtime
@pytest.mark.integration
def test_a_real_device_without_its_library_is_refused_with_the_command(emulator, tmp_path):
    """Realism over the serial link: the matched samples need a library built on this very
    device; the run stops before recording anything and names the command that builds it."""
    out = run("run", "realism", "--participant", "P08", "--device", f"serial:{emulator.port}",
              "--responder", "scripted", "--no-audio", "--data", str(tmp_path))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "matched_firm, matched_soft need(s) a library reproducing 'wood_on_foam'" in out.stderr
    assert (f"hapticlab library build --device serial:{emulator.port} --protocol realism "
            "--source wood_on_foam") in out.stderr
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("outputs, says", [
    (0, "PortAudio) lists none"),
    (None, "could not be asked which output devices exist"),
    (2, "lists 2 output device(s) but none could be opened"),
])
def test_an_audio_failure_says_what_to_check_first(monkeypatch, outputs, says):
    """Issue 30 (16): the preflight's audio failure read 'no audio output device: list index
    out of range'. Each failure starts with what is wrong and what to check, names
    --no-audio, and keeps PsychoPy's own words only as a detail at the end."""
    import types

    import psychopy

    from app import audio

    class Broken:
        def __init__(self, *a, **kw):
            raise IndexError("list index out of range")

    fake = types.SimpleNamespace(Sound=Broken)
    monkeypatch.setattr(psychopy, "sound", fake, raising=False)
    monkeypatch.setitem(sys.modules, "psychopy.sound", fake)
    monkeypatch.setattr(audio, "_outputs", lambda: outputs)
    with pytest.raises(audio.AudioUnavailable) as err:
        audio.Audio()
    msg = str(err.value)
    assert says in msg and "--no-audio" in msg, msg
    assert not msg.startswith(("list index", "IndexError")), msg
    if outputs != 0:
        assert msg.endswith("(PsychoPy said: IndexError: list index out of range)"), msg
