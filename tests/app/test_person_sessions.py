"""What changes when a person, not a program, takes a session: a second session of a
protocol needs --new-session, and the simulated device is paced by the wall clock."""

import sys

import pytest

from device import Scene

from .sim_sessions import SIX, run_six


@pytest.mark.integration
@pytest.mark.slow
def test_a_persons_second_session_of_a_protocol_needs_new_session(tmp_path, monkeypatch):
    """P01's next session of the same protocol is not created silently: the error lists what
    exists and how to go on; a dry run says so and runs."""
    from app.errors import UsageError

    assert run_six(tmp_path, "P01", "sim").status == "complete"
    said = []
    assert run_six(tmp_path, "P01", "sim", seed=4, say=said.append).status == "complete"
    assert any("already has six_on_nine session(s): ses-1 (complete, dry-run" in s
               for s in said)
    with pytest.raises(UsageError, match=r"already has six_on_nine session\(s\).*ses-1 .*ses-2 .*"
                                         r"--new-session"):
        run_six(tmp_path, "P01", "sim", seed=5, responder="person")
    assert sorted(f.name for f in (tmp_path / "data" / "sub-P01").iterdir()) == ["ses-1",
                                                                                  "ses-2"]
    # the command line: refused without --new-session; with it, the id check passes and the
    # next check stops (no terminal here for the operator) before anything is created
    import subprocess

    cmd = [sys.executable, "-m", "app", "run", str(SIX), "--participant", "P01", "--data",
           str(tmp_path / "data"), "--device", "sim", "--no-audio", "--seed", "5"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 2 and "--new-session" in out.stderr, out.stderr
    out = subprocess.run([*cmd, "--new-session"], capture_output=True, text=True, timeout=120,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 2 and "this one is the next" in out.stderr, out.stderr
    assert "preflight: operator keys: no terminal" in out.stderr, out.stderr
    assert len(list((tmp_path / "data" / "sub-P01").iterdir())) == 2


def test_a_person_on_the_simulated_device_is_paced_by_the_wall_clock():
    """Issue 30 (10): unpaced, a person's familiarization on `sim` produced 910 taps in 13 s.
    The session opens the simulator live when a person sits at it (its windows then report
    their pacing, which session.json keeps as `timing`), and unpaced for a program."""
    from app.api import open_device_for

    for person, paced in ((True, True), (False, False)):
        with open_device_for("sim", seed=1, person=person) as dev:
            dev.load_scene(Scene("firm", spring=680.0))
            dev.home()
            res = dev.run_window(0.1, from_first_contact=False)
            assert bool(res.timing) is paced, res.timing
            if paced:
                assert res.timing["achieved_rate_hz"] > 0
