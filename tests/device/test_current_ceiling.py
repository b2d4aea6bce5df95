"""The current ceiling has one home, DeviceInfo.ceiling: never above the device's rating, the
rating itself up to rounding; the device, the preflight and the session all ask it."""

import dataclasses

import pytest

from device import CurrentLimitError, open_device
from protocols import load_protocol


def test_the_ceiling_is_the_request_never_above_the_rating():
    with open_device("sim") as dev:
        info = dev.info
        r = info.current_limit
        assert info.ceiling(r / 2) == r / 2
        assert info.ceiling(r * (1 + 1e-13)) == r  # the rating, written with rounding
        with pytest.raises(CurrentLimitError, match=f"above this device's rating of {r:g} A"):
            info.ceiling(r * (1 + 1e-9))
        assert dev.set_current_limit(r * (1 + 1e-13)) == r == dev.current_limit
        with pytest.raises(CurrentLimitError):
            dev.set_current_limit(r * 1.5)
        assert dev.current_limit == r  # nothing changed


@pytest.mark.slow  # the session check opens a device and loads the realism protocol, ~1 s
def test_the_session_and_the_preflight_refuse_through_the_same_ceiling():
    from app.api._session import apply_limit
    from app.errors import UsageError
    from app.preflight import check_limit

    p = load_protocol("realism")
    with open_device("sim") as dev:
        r = dev.info.current_limit
        high = dataclasses.replace(p, limits=dataclasses.replace(p.limits, max_current=r * 1.5))
        with pytest.raises(UsageError, match=r"max_current: a current limit of .* is above "
                                             r"this device's rating"):
            apply_limit(high, dev)
        c = check_limit(high, dev)
        assert not c.ok and c.detail == f"the protocol's [limits] max_current: a current " \
            f"limit of {r * 1.5:g} A is above this device's rating of {r:g} A"
        assert apply_limit(p, dev)["current_limit_a"] == min(p.limits.max_current or r, r)
