"""Adaptive phases through the whole session path (issue 57): run by the simulated observer
on the simulated device, killed and resumed, recorded and analysed."""

from pathlib import Path

import pytest

from benchmarks.crash import kill_and_resume

pytestmark = [pytest.mark.integration, pytest.mark.slow]

JND_MINI = Path(__file__).parents[1] / "data" / "jnd_mini.toml"


def test_a_killed_adaptive_session_resumes_its_procedures_exactly(tmp_path):
    """kill -9 at random moments, then resume: every row kept, and the final rows — each
    trial's track, intensity and procedure state among them — those of the uninterrupted
    session (benchmarks.crash compares them column by column)."""
    r = kill_and_resume(4, protocol=str(JND_MINI), workdir=tmp_path, delay=(0.5, 3.0),
                        traces="none")
    assert r["kills"] == 4 and r["lost_rows_events"] == 0
    assert r["sequence_matches"], r["mismatched"]
