"""An API function behind each protocol command (issue 33): what ``protocol show`` and
``protocol validate`` print is what these return."""

import json
import subprocess
import sys

import pytest

from app.api import protocol_plan, validate_protocol
from protocols import ProtocolError


def test_the_plan_is_what_protocol_show_prints_as_json():
    plan = protocol_plan("realism", seed=3, participant="P01")
    shown = subprocess.run([sys.executable, "-m", "app", "protocol", "show", "realism",
                            "--seed", "3", "--participant", "P01", "--json"],
                           capture_output=True, text=True, check=True).stdout
    assert json.loads(shown) == json.loads(json.dumps(plan))
    trials = [t for ph in plan["phases"] for t in ph["trials"]]
    assert len(trials) == 45 and plan["duration_estimate"]["windows"] == 45
    # 45 windows of the protocol's 5 s, and 20 s a trial to place and answer (rule of thumb)
    est = plan["duration_estimate"]
    assert est["tapping_s"] == pytest.approx(45 * est["window_s"])
    assert est["total_s"] == pytest.approx(est["tapping_s"] + 45 * est["overhead_per_trial_s"])


def test_validate_returns_what_the_command_says():
    v = validate_protocol("identification", device="sim")
    assert (v["protocol"], v["samples"], v["phases"], v["trials"], v["device"]) == (
        "identification", 6, 1, 3, "sim")
    assert v["warnings"] == [] and v["notes"] == []
    with pytest.raises(ProtocolError, match="no-such-protocol"):
        validate_protocol("no-such-protocol")
