"""The growth rule (docs/wire-protocol.md §1b, issue 53 item 1): a client written from a
published version keeps talking to every device target, and the contract refuses a change
that would break such a client.

The old client here knows nothing of today's code: it reads the layouts version 2 was
first published with from ``device/serial/published.json`` (kept as data: LIMITS 20 bytes,
LINK_REPORT 148) and holds every frame to that document's rule, a body of exactly its
length, as the clients written three days ago did.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import struct
import time

import pytest
import serial

from device.serial import contract as C
from device.serial.firmware import CONFORMANCE_TARGETS
from device.serial.framing import FrameDecoder, encode_frame

from ..conftest import start_emulator, stop_emulator

PUBLISHED = json.loads(C.PUBLISHED.read_text())


# ------------------------------------------------------------------ the contract refuses
def _replace(name: str, **changes) -> tuple[C.Spec, ...]:
    return tuple(dataclasses.replace(s, **changes) if s.name == name else s for s in C.SPECS)


def _without(name: str, field: str) -> tuple[C.Field, ...]:
    return tuple(f for f in C.BY_NAME[name].fields if f.name != field)


def test_the_contract_keeps_every_published_version():
    assert C.growth_errors() == []
    assert set(C.published()) == {2, 3} and C.PROTOCOL == 3


def test_an_appended_field_is_the_one_change_a_message_may_take():
    limits = C.BY_NAME["LIMITS"]
    grown = _replace("LIMITS", fields=limits.fields + (C.Field("spare", "u16", since=3),))
    assert C.growth_errors(grown) == []
    # LIMITS.max_window_ms was appended so, after version 3's publication: its minimum
    # stays what was published, and a body of that length still fits
    assert limits.fields[-1].name == "max_window_ms"
    assert C.min_size(limits, 3) == limits.size(3) - 4
    assert C.growth_errors(_replace("LIMITS", fields=_without("LIMITS", "max_window_ms"))) == []


@pytest.mark.parametrize(("change", "says"), [
    # a field inserted before the last one (what LINK_REPORT's estop_max did within v2)
    (lambda: _replace("LIMITS", fields=C.BY_NAME["LIMITS"].fields[:2]
                      + (C.Field("spare", "u16"),) + C.BY_NAME["LIMITS"].fields[2:]),
     "LIMITS in version 2: frozen as published"),
    (lambda: _replace("LIMITS", fields=_without("LIMITS", "capabilities")),
     "LIMITS in version 3: its published fields"),
    (lambda: _replace("HELLO_ACK", fields=C.BY_NAME["HELLO_ACK"].fields[:-1]),
     "HELLO_ACK in version 2: frozen as published"),
    (lambda: _replace("STATUS", fields=tuple(dataclasses.replace(f, type="u16")
                                             if f.name == "state" else f
                                             for f in C.BY_NAME["STATUS"].fields)),
     "STATUS in version 3: its published fields"),
    (lambda: _replace("LINK_REPORT", fields=C.BY_NAME["LINK_REPORT"].fields
                      + (C.Field("spare", "u32", since=3),)),
     "LINK_REPORT in version 3: a message with an array never grows"),
    (lambda: _replace("CONTACT", type=0x9F), "CONTACT in version 2: type 0x90 became 0x9f"),
    (lambda: tuple(s for s in C.SPECS if s.name != "POSITION"),
     "POSITION in version 2: published, now gone"),
    (lambda: C.SPECS + (C.Spec(0x9A, "NEWS", "device", versions=(2, 3)),),
     "NEWS in version 2: version 2 is frozen"),
    (lambda: _replace("HELLO", fields=(C.Field("host_protocol", "u16"),)),
     "HELLO is read in every version"),
    (lambda: _replace("ESTOP", fields=(C.Field("why", "u8", since=3),)),
     "ESTOP is read in every version"),
])
def test_a_change_that_breaks_a_published_client_is_refused_by_name(change, says):
    errors = C.growth_errors(change())
    assert any(says in e for e in errors), errors


def test_make_contract_refuses_to_write_a_breaking_change(tmp_path, monkeypatch, capsys):
    """`make contract` (contract.main) writes nothing when the rule is broken."""
    monkeypatch.setattr(C, "SPECS", _replace("LIMITS", fields=_without("LIMITS", "capabilities")))
    monkeypatch.setattr(C, "BY_NAME", {s.name: s for s in C.SPECS})
    monkeypatch.setattr(C, "HEADER", tmp_path / "hl_contract.h")
    monkeypatch.setattr(C, "DOC", tmp_path / "wire-protocol.md")
    assert C.main([]) == 1
    assert "LIMITS in version 3" in capsys.readouterr().err
    assert not (tmp_path / "hl_contract.h").exists()


# ------------------------------------------------------------------ the old client
class OldClient:
    """A version-2 host from the document as first published: exact lengths, its layouts
    from ``published.json``, nothing from today's messages."""

    LAYOUT = PUBLISHED["2"]["messages"]
    CODES = {"u8": "B", "u16": "H", "u32": "I", "u64": "Q", "i16": "h", "i32": "i",
             "f32": "f"}

    def __init__(self, port: str):
        self.port = serial.Serial(port, timeout=0.01)
        self.dec = FrameDecoder()
        self.seq = 0
        self.by_type = {m["type"]: (name, m) for name, m in self.LAYOUT.items()}
        self.sent = time.monotonic()
        self.pending: list = []  # frames decoded, not yet looked at

    def fmt(self, name: str) -> str:
        return "<" + "".join(self.CODES.get(t, t[5:] + "s") for _, t in
                             self.LAYOUT[name]["fields"])

    def send(self, name: str, *values, version: int = 2) -> int:
        self.seq += 1
        self.port.write(encode_frame(self.LAYOUT[name]["type"], self.seq,
                                     struct.pack(self.fmt(name), *values), version))
        self.sent = time.monotonic()
        return self.seq

    def read(self, want, limit: float = 10.0) -> tuple[str, dict, tuple]:
        """The first frame ``want(name, fields)`` accepts, every frame held to the rule."""
        end = time.monotonic() + limit
        while time.monotonic() < end:
            if time.monotonic() - self.sent > 0.025:
                self.send("HEARTBEAT")
            if not self.pending:
                self.pending = self.dec.feed(self.port.read(max(1, self.port.in_waiting)))
            while self.pending:
                frame = self.pending.pop(0)
                name, m = self.by_type[frame.type]  # a type it does not know: KeyError
                fixed = struct.calcsize(self.fmt(name))
                body = frame.body
                assert frame.version == 2, (name, frame.version)
                if m["items"] is None:
                    assert len(body) == fixed, (name, len(body), fixed)
                    items = ()
                else:
                    code = self.CODES[m["items"]]
                    size = struct.calcsize("<" + code)
                    assert len(body) >= fixed and (len(body) - fixed) % size == 0, name
                    items = struct.unpack(f"<{(len(body) - fixed) // size}{code}", body[fixed:])
                fields = dict(zip((n for n, _ in m["fields"]),
                                  struct.unpack(self.fmt(name), body[:fixed]), strict=True))
                if want(name, fields):
                    return name, fields, items
        raise AssertionError("the device did not answer")

    def ask(self, name: str, *values) -> int:
        seq = self.send(name, *values)
        return self.read(lambda n, f: n == "ACK" and f["ack_seq"] == seq)[1]["status"]


NO_QEMU = pytest.mark.skipif(shutil.which("qemu-system-arm") is None,
                             reason="qemu-system-arm missing: `make test` installs it")
TARGETS = [*CONFORMANCE_TARGETS,
           pytest.param("qemu", marks=[pytest.mark.qemu, pytest.mark.slow, NO_QEMU])]


@pytest.mark.integration
@pytest.mark.firmware
@pytest.mark.parametrize("target", TARGETS)
def test_a_client_of_version_2_as_first_published_still_runs_a_trial(target):
    """HELLO offering 2, HELLO_ACK and LIMITS (20 bytes), a spring scene, HOME, a 0.2-s
    window with its trace chunks and WINDOW_DONE, LINK_QUERY and its 148-byte LINK_REPORT:
    every frame version 2, every body its published length."""
    emu = start_emulator("--firmware", target, "--seed", "3")
    client = OldClient(emu.port)
    try:
        client.port.write(b"\x00")
        for _ in range(20):  # a device may start listening after its port opens (QEMU)
            client.send("HELLO", 2, version=1)
            try:
                _, ack, _ = client.read(lambda n, f: n == "HELLO_ACK", 0.5)
                break
            except AssertionError:
                continue
        else:
            raise AssertionError("no HELLO_ACK")
        assert ack["protocol"] == 2
        _, limits, _ = client.read(lambda n, f: n == "LIMITS")
        assert limits["max_decimation"] >= 1 and limits["channels"] & 1
        assert client.ask("TRACE_CONFIG", 1, 1) == 0  # position alone
        spring = (1, 1, 0, 680.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0, 0, 1.0)
        assert client.ask("SCENE_BEGIN", *spring) == 0
        assert client.ask("SCENE_COMMIT", 1, 0) == 0
        assert client.ask("HOME", 20_000) == 0
        assert client.ask("START_WINDOW", 9, 200, 200, 0) == 0
        records = []

        def until_done(name, f):
            if name == "TRACE_CHUNK":
                records.append(f["n"])
            return name == "WINDOW_DONE"

        _, done, _ = client.read(until_done, 30.0)
        assert done["window_id"] == 9 and done["n_ticks"] == round(0.2 * ack["servo_rate_hz"])
        assert sum(records) == done["n_ticks"]
        assert client.ask("LINK_QUERY", 0) == 0
        _, report, gaps = client.read(lambda n, f: n == "LINK_REPORT")
        assert report["frames"] >= 8 and len(gaps) == 64
        assert client.ask("ZERO") == 0
    finally:
        client.port.close()
        stop_emulator(emu)
        print(f"the device's stderr:\n{emu.stderr()}")


@pytest.mark.integration
def test_this_host_adapts_to_a_device_that_speaks_version_2():
    """The other side of the rule: hapticlab's host reads a version-2 device in version 2's
    layouts, and what that version does not carry is None, not a made-up 0."""
    from device.serial.link import Link

    emu = start_emulator("--seed", "3")
    link = Link(emu.port)
    try:
        ack = link.hello(2)  # what a device that speaks only version 2 chooses
        assert ack.protocol == 2 and link.version == 2
        lim = link.limits
        assert lim.table_items > 0 and lim.link_bytes_s == 0
        assert lim.capabilities is None and lim.can("seeded") is None
        assert lim.tick_max_us is None and lim.max_window_ms is None
        report = link.device_report()
        assert report["frames"] >= 1 and report["estop_max_ms"] is None
    finally:
        link.shutdown()
        stop_emulator(emu)
