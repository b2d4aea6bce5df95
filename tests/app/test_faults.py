"""Sessions that survive every fault and every bad input (issue: locks, headers, line
endings, the protocol's current limit, no traceback anywhere)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from analysis.session_format import header_line, read_trials

CLI = [sys.executable, "-m", "app"]
DATA = Path(__file__).resolve().parents[1] / "data" / "protocols"

MINI = (DATA.parent / "mini_two.toml").read_text()
DRY = ["--dry-run", "--no-audio", "--quiet"]
SPRINGS = MINI.replace('scene.transient = { kind = "pulse", gain = 5.7, duration = 0.02 }\n', "")
KEY = slice(0, 15)  # the columns a resumed session must reproduce (not the times)


def run(*args, **kw):
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600, **kw)


def one_line_error(out, fragment):
    """A user error: exit 2, one line naming what is wrong, no traceback."""
    assert out.returncode == 2, (out.returncode, out.stderr)
    assert "Traceback" not in out.stderr, out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.startswith("hapticlab: error")]
    assert len(lines) == 1 and fragment in lines[0], out.stderr


@pytest.fixture
def mini(tmp_path):
    p = tmp_path / "mini.toml"
    p.write_text(MINI)
    return p


@pytest.fixture
def session(mini, tmp_path):
    """A complete dry-run session of the mini protocol and its rows."""
    out = run("run", str(mini), "--participant", "P01", "--seed", "3", "--data",
              str(tmp_path / "d"), *DRY)
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "d" / "sub-P01" / "ses-1"
    return folder, (folder / "trials.tsv").read_text()


def interrupted(folder: Path, keep_rows: int | None = None, text: str | None = None) -> None:
    """As a crash would leave it: status interrupted, only the first rows (or ``text``)."""
    if text is None:
        lines = (folder / "trials.tsv").read_text().splitlines(keepends=True)
        text = "".join(lines[: 1 + keep_rows])
    (folder / "trials.tsv").write_bytes(text.encode() if isinstance(text, str) else text)
    meta = json.loads((folder / "session.json").read_text())
    meta["status"] = "interrupted"
    (folder / "session.json").write_text(json.dumps(meta))


def cols(text: str) -> list[list[str]]:
    return [ln.split("\t")[KEY] for ln in text.splitlines()]


# ------------------------------------------------------------------ 1–2: headers, line endings
def test_the_header_is_durable_before_anything_else(tmp_path):
    from app.recorder import SessionFiles

    folder = tmp_path / "ses-1"
    folder.mkdir()
    f = SessionFiles(folder)
    f.start(MINI)
    assert (folder / "trials.tsv").read_text() == header_line()
    assert (folder / "protocol.toml").read_text() == MINI


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.parametrize("damage", ["empty", "missing", "header only"])
def test_resume_repairs_a_session_stopped_before_its_first_row(session, damage):
    folder, full = session
    interrupted(folder, 0)
    if damage == "empty":
        (folder / "trials.tsv").write_bytes(b"")
    elif damage == "missing":
        (folder / "trials.tsv").unlink()
    out = run("resume", str(folder))
    assert out.returncode == 0, out.stderr
    text = (folder / "trials.tsv").read_text()
    assert text.startswith(header_line()) and cols(text) == cols(full)


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.parametrize("ending", ["\r\n", "\r", "bom+\n", "bom+\r\n"])
def test_any_line_ending_or_bom_resumes_and_is_written_back_canonical(session, ending):
    """A file a spreadsheet opened and saved: CRLF, Mac CR-only, a UTF-8 byte-order mark."""
    folder, full = session
    lines = full.splitlines()[:3]  # header + 2 rows
    eol = ending.removeprefix("bom+")
    raw = (eol.join(lines) + eol).encode()
    if ending.startswith("bom"):
        raw = b"\xef\xbb\xbf" + raw
    interrupted(folder, text=raw)
    rows, torn = read_trials(folder / "trials.tsv")
    assert len(rows) == 2 and torn is None  # every recorded row is read
    out = run("resume", str(folder))
    assert out.returncode == 0, out.stderr
    assert "rewrote trials.tsv with LF line endings" in out.stderr
    assert not (folder / "trials.torn.tsv").exists()
    raw = (folder / "trials.tsv").read_bytes()
    assert b"\r" not in raw and not raw.startswith(b"\xef\xbb\xbf")
    assert cols(raw.decode()) == cols(full)


# ------------------------------------------------------------------ 3: one writer
@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_a_second_resume_of_the_same_session_is_refused(tmp_path, emulator):
    """Two resumes of one session at once once wrote 92 rows instead of 51. The first holds
    the session's lock (running in real time over the serial emulator), the second stops."""
    proto = tmp_path / "two.toml"
    proto.write_text(MINI.replace("repetitions = 2", "repetitions = 3"))
    data = tmp_path / "d"
    ref = run("run", str(proto), "--participant", "P01", "--seed", "4", "--data",
              str(tmp_path / "ref"), *DRY)
    assert ref.returncode == 0, ref.stderr
    out = run("run", str(proto), "--participant", "P01", "--seed", "4", "--data", str(data),
              *DRY)
    assert out.returncode == 0, out.stderr
    folder = data / "sub-P01" / "ses-1"
    interrupted(folder, 1)
    first = subprocess.Popen([*CLI, "resume", str(folder), "--quiet", "--device",
                              f"serial:{emulator.port}"], stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 30
    while time.monotonic() < end and not ((folder / "session.lock").exists() and (
            folder / "session.lock").read_text().startswith(f"{first.pid}\t")):
        time.sleep(0.02)
    second = run("resume", str(folder))
    assert first.wait(timeout=120) == 0, first.stderr.read()
    one_line_error(second, "session in use by PID")
    assert f"PID {first.pid}" in second.stderr
    ref_rows = (tmp_path / "ref" / "sub-P01" / "ses-1" / "trials.tsv").read_text()
    got = (folder / "trials.tsv").read_text()
    assert len(got.splitlines()) == len(ref_rows.splitlines())  # nothing written twice


@pytest.mark.integration
@pytest.mark.slow
def test_the_lock_dies_with_its_process(session):
    folder, full = session
    interrupted(folder, 1)
    proc = subprocess.Popen([*CLI, "resume", str(folder), "--quiet"])
    end = time.monotonic() + 30
    while time.monotonic() < end and not (folder / "session.lock").read_text().startswith(
            str(proc.pid)):
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    out = run("resume", str(folder))
    assert out.returncode == 0, out.stderr
    assert cols((folder / "trials.tsv").read_text()) == cols(full)


@pytest.mark.integration
@pytest.mark.slow
def test_two_runs_of_one_participant_at_once_get_two_sessions(mini, tmp_path):
    procs = [subprocess.Popen([*CLI, "run", str(mini), "--participant", "P02", "--seed", str(s),
                               "--data", str(tmp_path), *DRY]) for s in (1, 2)]
    assert [p.wait(timeout=120) for p in procs] == [0, 0]
    seeds = sorted(json.loads((tmp_path / "sub-P02" / f"ses-{n}" / "session.json")
                              .read_text())["seed"] for n in (1, 2))
    assert seeds == [1, 2]


# ------------------------------------------------------------------ 4: cross-checks
@pytest.mark.integration
@pytest.mark.slow
def test_resume_refuses_files_that_do_not_belong_together(session):
    folder, full = session
    interrupted(folder, 2)
    meta = json.loads((folder / "session.json").read_text())
    meta["participant"]["id"] = "P99"
    (folder / "session.json").write_text(json.dumps(meta))
    one_line_error(run("resume", str(folder)), "trials.tsv:2: participant is 'P01' but "
                                               "session.json says 'P99'")
    meta["participant"]["id"] = "P01"
    (folder / "session.json").write_text(json.dumps(meta))
    lines = (folder / "trials.tsv").read_text().splitlines(keepends=True)
    lines[2] = lines[2].replace("P01\t1\t", "P01\t2\t", 1)  # another session's row
    (folder / "trials.tsv").write_text("".join(lines))
    one_line_error(run("resume", str(folder)), "trials.tsv:3: session is '2'")
    meta.pop("seed")
    (folder / "session.json").write_text(json.dumps(meta))
    one_line_error(run("resume", str(folder)), "missing key(s) seed")


# ------------------------------------------------------------------ 5: replayed participant
@pytest.mark.integration
@pytest.mark.slow
def test_a_resumed_simulated_session_equals_the_uninterrupted_one(tmp_path):
    """Cut after a trial, a simulated participant's session resumes to the same rows: the
    participant's memory (its familiarization, the range of what it felt) is replayed from
    the recorded attempts. The sample: after the familiarization, after the first rated
    trial, half way and before the last row (`hapticlab bench crash --boundaries all` cuts
    a whole realism session after every row)."""
    from benchmarks.crash import TIMES, resume_after_rows

    assert not set(TIMES) & set(header_line().split("\t")[KEY])  # every column but the times
    r = resume_after_rows(str(DATA / "six_on_nine.toml"), rows="sample",
                          workdir=tmp_path / "w")
    assert r["rows"] >= 13 and r["after"] == [1, 2, r["rows"] // 2, r["rows"] - 1], r
    assert (r["divergent"], r["failed"]) == ([], []), r


def test_the_boundary_sample_meets_every_phase_change():
    from benchmarks.crash import sample_boundaries

    assert sample_boundaries(["warmup"] + ["main"] * 12) == [1, 2, 6, 12]
    phases = ["fam"] + ["demo"] * 11 + ["test"] * 33
    assert sample_boundaries(phases) == [1, 2, 12, 13, 22, 44]
    assert sample_boundaries(["a", "a"]) == [1]


# ------------------------------------------------------------------ 6: bounded loops
@pytest.mark.integration
@pytest.mark.slow
def test_an_unreachable_surface_or_a_window_nobody_taps_still_ends(mini, tmp_path):
    far = mini.read_text().replace('scene.spring = 680.0', 'scene.spring = 680.0\n'
                                   'scene.surface_height = 1e300')
    bad = tmp_path / "far.toml"
    bad.write_text(far)
    one_line_error(run("protocol", "validate", str(bad)), "surface_height: must be <= 0.5")
    one_line_error(run("run", str(bad), "--participant", "P03", "--data", str(tmp_path / "x"),
                       *DRY), "surface_height")
    assert not (tmp_path / "x").exists()
    # a window that ends before anyone can tap: every attempt times out, capped
    quick = tmp_path / "quick.toml"
    quick.write_text(MINI.replace("timeout = 10.0", "timeout = 0.001") +
                     "[attempts]\nmax_timeouts = 2\n")
    out = run("run", str(quick), "--participant", "P04", "--data", str(tmp_path / "q"), *DRY)
    assert out.returncode == 0, out.stderr
    rows, _ = read_trials(tmp_path / "q" / "sub-P04" / "ses-1" / "trials.tsv")
    assert [r["status"] for r in rows].count("excluded_timeout") == 4
    assert [r["status"] for r in rows].count("timed_out") == 4 and len(rows) == 8


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.parametrize("transient, field", [
    ('{ kind = "sinusoid", gain = 1.0, decay_time = 0.055, frequency = 1e308 }', "frequency"),
    ('{ kind = "sinusoid", gain = 1.0, decay_time = 0.055, frequency = 10000.0 }', "frequency"),
    ('{ kind = "q_sinusoid", slope = -100.0, decay = 1e-9, frequency = 100.0 }', "decay"),
    ('{ kind = "q_sinusoid", slope = -100.0, decay = 1e9, frequency = 100.0 }', "decay"),
    ('{ kind = "pulse", gain = 5.7, duration = 1e-7 }', "duration"),
    ('{ kind = "pulse", gain = 5.7, duration = 1e6 }', "duration"),
])
def test_transients_a_device_cannot_play_are_refused_before_anything_runs(mini, tmp_path,
                                                                           transient, field):
    p = tmp_path / "t.toml"
    p.write_text(MINI.replace('{ kind = "pulse", gain = 5.7, duration = 0.02 }', transient))
    # (a decay past any device's — 1e9 1/s — is refused as data, the rest by the device)
    one_line_error(run("protocol", "validate", str(p), "--device", "sim"),
                   f"samples[1].scene.transient.{field}: ")
    one_line_error(run("run", str(p), "--participant", "P05", "--data", str(tmp_path / "x"),
                       *DRY), f"{field}:")
    assert not (tmp_path / "x").exists()


@pytest.mark.integration
def test_a_library_file_that_does_not_exist_is_refused_before_recording(tmp_path):
    text = (Path(__file__).resolve().parents[2] / "protocols" / "realism.toml").read_text()
    p = tmp_path / "r.toml"
    p.write_text(text.replace('source = "wood_on_foam", attenuation = 0.8 }',
                              'source = "wood_on_foam", attenuation = 0.8, '
                              'path = "/nowhere/lib.npz" }', 1))
    one_line_error(run("run", str(p), "--participant", "P06", "--data", str(tmp_path / "x"),
                       *DRY), "/nowhere/lib.npz: no such library file")
    assert not any((tmp_path / "x").rglob("trials.tsv")) if (tmp_path / "x").exists() else True


# ------------------------------------------------------------------ 7–8: current, NaN
@pytest.mark.integration
def test_the_protocols_current_limit_is_applied_on_the_device(mini, tmp_path):
    p = tmp_path / "low.toml"  # a spring pressed 4 mm pushes 2.7 N: 1.3 A unclamped
    p.write_text(SPRINGS + "[limits]\nmax_current = 0.05\n")
    out = run("run", str(p), "--participant", "P07", "--data", str(tmp_path), "--seed", "2",
              "--dry-run", "--no-audio", "--quiet", "--traces", "full")
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "sub-P07" / "ses-1"
    meta = json.loads((folder / "session.json").read_text())
    assert meta["limits"] == {"current_limit_a": 0.05, "device_rating_a": 1.4,
                              "protocol_max_current_a": 0.05}
    peak = max(float(np.abs(np.load(t)["current"]).max()) for t in folder.glob("traces/*.npz"))
    assert 0.04 < peak <= 0.05 + 1e-6  # clamped at the protocol's 0.05 A, not the 1.4 A rating
    rows, _ = read_trials(folder / "trials.tsv")
    assert any(r["status"] == "saturated" for r in rows)


@pytest.mark.realtime
@pytest.mark.integration
@pytest.mark.slow
def test_the_current_limit_goes_over_the_serial_link(emulator, mini, tmp_path):
    p = tmp_path / "low.toml"
    p.write_text(SPRINGS.replace("repetitions = 2", "repetitions = 1")
                 + "[limits]\nmax_current = 0.05\n")
    out = run("run", str(p), "--participant", "P08", "--data", str(tmp_path), "--device",
              f"serial:{emulator.port}", "--responder", "scripted", "--no-audio", "--quiet",
              "--traces", "full")
    assert out.returncode == 0, out.stderr
    folder = tmp_path / "sub-P08" / "ses-1"
    peak = max(float(np.abs(np.load(t)["current"]).max()) for t in folder.glob("traces/*.npz"))
    assert peak <= 0.05 + 1e-6
    assert "host: current limit 50 mA" in emulator.stderr()


def test_a_non_finite_command_never_reaches_the_amplifier():
    from device import Scene, TransientTable, open_device
    from device.scene import TableTransient

    table = TransientTable([1.0], np.full((1, 50), 1.0))
    object.__setattr__(table, "forces", np.full((1, 50), np.nan))  # past every check
    with open_device("sim", seed=1) as dev:
        dev.load_scene(Scene("nan", spring=680.0, transient=TableTransient(table)))
        dev.home()
        res = dev.run_window(1.0)
        cur = res.traces["current"]
        assert np.all(np.isfinite(cur))
        assert res.faults and res.faults[0].code == "nan_command"
        after = res.traces["t"] >= res.faults[0].t
        assert np.all(cur[after] == 0.0) and dev.fault.code == "nan_command"


# ------------------------------------------------------------------ 9: I/O errors
@pytest.mark.integration
def test_a_data_path_that_is_not_a_folder(mini, tmp_path):
    one_line_error(run("run", str(mini), "--participant", "P09", "--data", "/dev/null", *DRY),
                   "not a folder")
    f = tmp_path / "file"
    f.write_text("x")
    one_line_error(run("run", str(mini), "--participant", "P09", "--data", str(f), *DRY),
                   "not a folder")


@pytest.mark.integration
def test_session_files_are_readable_by_colleagues(session):
    folder, _ = session
    for name in ("session.json", "trials.tsv", "protocol.toml"):
        assert (folder / name).stat().st_mode & 0o044 == 0o044, name  # with umask 022


@pytest.fixture
def small_fs(tmp_path):
    """A 96-KiB tmpfs (root may mount one; elsewhere the test is skipped with the reason)."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=96k", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small file system here: {r.stderr.strip()}")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


@pytest.mark.integration
def test_a_full_disk_stops_the_session_cleanly_and_it_resumes(mini, small_fs):
    p = small_fs / "mini.toml"  # written before the disk fills
    p.write_text(MINI.replace("repetitions = 2", "repetitions = 8"))
    # fill the disk but for ~10 KiB: the header, session.json and a few rows fit
    free = os.statvfs(small_fs).f_bavail * os.statvfs(small_fs).f_frsize
    (small_fs / "ballast").write_bytes(b"x" * (free - 12 * 1024))
    env = {**os.environ}
    out = subprocess.run([*CLI, "run", str(p), "--participant", "P10", "--data",
                          str(small_fs / "d"), *DRY[:-1], "--traces", "none"],
                         capture_output=True, text=True, timeout=300, env=env)
    folder = small_fs / "d" / "sub-P10" / "ses-1"
    if out.returncode == 2:  # refused up front: not even the session's files fit
        one_line_error(out, "free")
        return
    assert out.returncode == 3, out.stderr
    assert "no space left" in out.stderr and "Traceback" not in out.stderr
    assert "resume" in out.stderr
    rows_then, torn = read_trials(folder / "trials.tsv")
    assert (folder / "trials.tsv").read_text().startswith(header_line())
    (small_fs / "ballast").unlink()  # the operator frees space
    again = run("resume", str(folder), "--quiet")
    assert again.returncode == 0, again.stderr
    rows, _ = read_trials(folder / "trials.tsv")
    assert rows[: len(rows_then)] == rows_then and sum(r["status"] == "valid"
                                                       for r in rows) == 16


@pytest.mark.integration
def test_a_read_only_file_system_is_refused_before_the_device_opens(mini, small_fs):
    r = subprocess.run(["mount", "-o", "remount,ro", str(small_fs)], capture_output=True)
    if r.returncode:
        pytest.skip("cannot remount read-only here")
    one_line_error(run("run", str(mini), "--participant", "P11", "--data",
                       str(small_fs / "d"), *DRY), "read-only file system")


@pytest.mark.integration
def test_permission_denied_is_one_line(mini, tmp_path):
    """A folder this user may not write: chmod for anyone but root; root ignores modes, so
    as root the folder is made immutable (chattr +i), which refuses root too."""
    locked = tmp_path / "locked"
    locked.mkdir()
    if os.geteuid() == 0:
        r = subprocess.run(["chattr", "+i", str(locked)], capture_output=True, text=True)
        if r.returncode:
            pytest.skip(f"cannot make a folder immutable here: {r.stderr.strip()}")
    else:
        locked.chmod(0o555)
    try:
        out = run("run", str(mini), "--participant", "P12", "--data", str(locked / "d"), *DRY)
        one_line_error(out, "data folder")
        assert "permission denied" in out.stderr or "not permitted" in out.stderr
    finally:
        if os.geteuid() == 0:
            subprocess.run(["chattr", "-i", str(locked)], capture_output=True)
        locked.chmod(0o755)


@pytest.mark.integration
def test_file_too_large_is_a_clean_interruption(mini, tmp_path):
    import resource

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (8_000, 8_000))

    p = tmp_path / "long.toml"
    p.write_text(MINI.replace("repetitions = 2", "repetitions = 40"))
    out = subprocess.run([*CLI, "run", str(p), "--participant", "P13", "--data",
                          str(tmp_path / "d"), *DRY, "--traces", "none"],
                         capture_output=True, text=True, timeout=300, preexec_fn=limit)
    # --quiet silences progress, never the reason a session stopped
    assert out.returncode == 3 and "file too large" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr and "hapticlab resume" in out.stderr
    folder = tmp_path / "d" / "sub-P13" / "ses-1"
    assert (folder / "trials.tsv").read_text().startswith(header_line())


# ------------------------------------------------------------------ 10–11: hostile inputs
@pytest.mark.integration
@pytest.mark.slow
def test_hostile_session_files_give_one_line_errors(session, tmp_path):
    folder, full = session
    data = folder.parents[1]
    # a rating off the scale, then an infinite one: named by file and line
    lines = full.splitlines(keepends=True)
    cells = lines[2].split("\t")
    cells[14] = "99"
    (folder / "trials.tsv").write_text("".join(lines[:2]) + "\t".join(cells) + "".join(lines[3:]))
    one_line_error(run("analyze", str(data), "--out", str(tmp_path / "r")),
                   "trials.tsv:3: rating 99 is outside the scale 1–7")
    ok = run("analyze", str(data), "--out", str(tmp_path / "r"), "--drop-invalid",
             "--format", "json,md")
    assert ok.returncode in (0, 1), ok.stderr  # 1 when nothing is left to analyse
    rep = json.loads((tmp_path / "r" / "report.json").read_text())
    assert rep["selection"]["rows_left_out"][0]["line"] == 3
    assert "rating 99 is outside the scale" in (tmp_path / "r" / "report.md").read_text()
    cells[14] = "inf"
    (folder / "trials.tsv").write_text("".join(lines[:2]) + "\t".join(cells) + "".join(lines[3:]))
    one_line_error(run("analyze", str(data), "--out", str(tmp_path / "r")),
                   "rating inf is not a finite number")
    cells[14] = ""
    (folder / "trials.tsv").write_text("".join(lines[:2]) + "\t".join(cells) + "".join(lines[3:]))
    one_line_error(run("analyze", str(data), "--out", str(tmp_path / "r")),
                   "a valid trial without a rating")
    # a missing column
    (folder / "trials.tsv").write_text("\n".join("\t".join(ln.split("\t")[:14] + ln.split(
        "\t")[15:]) for ln in full.splitlines()) + "\n")
    one_line_error(run("analyze", str(data), "--out", str(tmp_path / "r")), "missing rating")
    (folder / "trials.tsv").write_text(full)
    # session.json without a key every reader needs
    meta = json.loads((folder / "session.json").read_text())
    meta["protocol"].pop("sha256")
    (folder / "session.json").write_text(json.dumps(meta))
    one_line_error(run("analyze", str(data), "--out", str(tmp_path / "r")),
                   "missing key(s) protocol.sha256")


@pytest.mark.integration
@pytest.mark.slow
def test_a_truncated_trace_is_skipped_not_fatal(tmp_path):
    for pid, seed in (("P01", 1), ("P02", 2)):  # exactly two participants: no ZeroDivision
        out = run("run", str(DATA / "six_on_nine.toml"), "--participant", pid, "--seed",
                  str(seed), "--data", str(tmp_path / "d"), "--dry-run", "--no-audio",
                  "--quiet", "--traces", "contacts")
        assert out.returncode == 0, out.stderr
    trace = sorted((tmp_path / "d").rglob("traces/*.npz"))[5]
    trace.write_bytes(trace.read_bytes()[:100])
    out = run("analyze", str(tmp_path / "d"), "--out", str(tmp_path / "r"))
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.integration
def test_hostile_protocols_and_labels(tmp_path, mini):
    deep = tmp_path / "deep.toml"
    deep.write_text('[protocol]\nname = "x"\na = ' + "[" * 5000 + "]" * 5000 + "\n")
    one_line_error(run("protocol", "validate", str(deep)), "nested too deeply")
    one_line_error(run("run", str(mini), "--participant", "P14", "--group", "a|b", "--data",
                       str(tmp_path), *DRY), "group 'a|b'")
    notutf = tmp_path / "bin.toml"
    notutf.write_bytes(b"\xff\xfe\x00garbage")
    one_line_error(run("protocol", "validate", str(notutf)), "not a UTF-8 text file")


@pytest.mark.integration
def test_text_in_report_tables_is_escaped(session, tmp_path):
    folder, _ = session
    meta = json.loads((folder / "session.json").read_text())
    meta["participant"]["group"] = "a|b<script>"  # written by hand into an old session
    (folder / "session.json").write_text(json.dumps(meta))
    from analysis.report_text import table as _table

    md = _table([{"x": "a|b<script>", "y": 1}])
    assert md.splitlines()[2] == "| a\\|b&lt;script&gt; | 1 |"


def test_the_sample_of_write_points_meets_every_way_the_session_writes():
    """benchmarks.crash.sample_points on a two-trial session's points as the harness logs
    them: each kind at each file once (temporary names and trial numbers aside), the header
    of trials.tsv and the first row's append, and the last update of session.json."""
    from benchmarks.crash import sample_points

    ses = "/d/sub-P01/ses-1"
    log = [("mkdir", "/d/sub-P01"), ("mkdir", ses), ("mkdir", f"{ses}/traces"),
           ("open", f"{ses}/session.lock"), ("write", f"{ses}/session.lock")]
    atomic = [("open", "{}.tmp"), ("write", "{}.tmp"), ("fsync", "{}.tmp")]
    log += [(k, f"{ses}/.protocol.toml.ab12cd34.tmp") for k, _ in atomic]
    log += [("rename", f"{ses}/protocol.toml"), ("fsync", ses)]
    row = [("open", f"{ses}/trials.tsv"), ("write", f"{ses}/trials.tsv"),
           ("fsync", f"{ses}/trials.tsv")]
    log += [*row, ("fsync", ses)]  # the header: 11-14
    for tmp in ("q1w2e3r4", "z9x8c7v6"):  # session.json written, then its status updated
        log += [(k, f"{ses}/.session.json.{tmp}.tmp") for k, _ in atomic]
        log += [("rename", f"{ses}/session.json"), ("fsync", ses)]
        if tmp == "q1w2e3r4":
            for trial in (1, 2):  # each trial: its trace, then its row
                log += [(k, f"{ses}/traces/.trial-000{trial}-0.npz.{tmp}.tmp")
                        for k, _ in atomic]
                log += [("fsync", f"{ses}/traces"), *row]
    chosen = sample_points(log)
    kinds = {kind for kind, _ in log}
    assert {log[k - 1][0] for k in chosen} == kinds
    header, first_row, second_row = [k for k, point in enumerate(log, 1)
                                     if point == ("write", f"{ses}/trials.tsv")]
    assert {header, first_row} <= set(chosen) and second_row not in chosen
    last_json_write = max(k for k, (kind, path) in enumerate(log, 1)
                          if kind == "write" and ".session.json." in path)
    last_rename = max(k for k, (kind, path) in enumerate(log, 1)
                      if kind == "rename" and path.endswith("session.json"))
    assert {last_json_write, last_rename} <= set(chosen)
    # the second trial's trace and the fsyncs that repeat are left to bench crash
    second = [k for k, (_, path) in enumerate(log, 1) if "trial-0002" in path]
    assert second and not set(second) & set(chosen)
    assert len(chosen) < len(log)


# ------------------------------------------------------------------ 8: the write points
# `hapticlab bench crash --points all` kills at every one of them (56 runs of the CLI for this
# protocol, 140 s on a quiet machine); the suite kills at a sample that meets each way the
# session writes (benchmarks.crash.sample_points). The bound is for a hung test, not a
# speed check: a loaded run of every point once passed the suite's 300-s bound
@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_kill_at_the_write_points_loses_nothing(tmp_path):
    """In the manner of SQLite's crash tests: the session is killed right after a write point
    in the data folder (open, write, fsync, rename, mkdir) and half way through each write
    (a torn write), then resumed; every row seen after the kill is kept, no trials.tsv is
    ever without its header, and the final rows equal the uninterrupted run's. The points:
    the first of each kind at each file, the first row's append and the last update of
    session.json (`hapticlab bench crash --points all` takes every point of a whole
    realism session)."""
    from benchmarks.crash import kill_at_points

    p = tmp_path / "two.toml"
    p.write_text(MINI.replace("repetitions = 2", "repetitions = 1"))
    r = kill_at_points(str(p), points="sample", workdir=tmp_path / "w", traces="contacts")
    assert r["points"] >= 30 and set(r["by_kind"]) == {"open", "write", "fsync", "rename",
                                                        "mkdir"}
    assert set(r["killed_at"].values()) == set(r["by_kind"])  # every kind of point
    writes = sum(kind == "write" for kind in r["killed_at"].values())
    assert r["runs"] == len(r["killed_at"]) + writes  # each write whole and torn
    assert (r["lost_rows"], r["headerless"], r["divergent"], r["failed"],
            r["not_killed"]) == (0, 0, 0, 0, 0), r["problems"]
