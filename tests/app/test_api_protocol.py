"""An API function behind each protocol command (issue 33): what ``protocol show`` and
``protocol validate`` print is what these return."""

import json
import subprocess
import sys

import pytest

from app.api import protocol_plan, validate_protocol
from protocols import ProtocolError


@pytest.mark.integration
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


def test_power_is_an_api_function_with_named_refusals():
    from app.api import power
    from app.errors import UsageError

    pw = power("realism", subjects=[5, 10], reps=[1, 2], experiments=200)
    assert (pw["protocol"], pw["phase"], pw["comparisons"]) == ("realism", "testing", 55)
    assert pw["sd"] == {"sd_trial": 0.9, "sd_interaction": 0.5, "sd_subject": 0.8}
    t = pw["table"]
    assert sorted(zip(t["subjects"], t["reps"], strict=True)) == [(5, 1), (5, 2), (10, 1), (10, 2)]
    assert ((0 <= t["power"]) & (t["power"] <= 1)).all() and (t["ci_halfwidth"] > 0).all()
    with pytest.raises(UsageError, match="at least 2 subjects"):
        power("realism", subjects=[1], reps=[1])
    with pytest.raises(UsageError, match="no analysed rating phase"):
        power("identification", subjects=[5], reps=[1])
