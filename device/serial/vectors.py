"""Test vectors of the wire protocol: one file that every implementation decodes.

``docs/wire-vectors.txt`` holds one frame per line (as sent on the wire, delimiter
excluded) and what a receiver must make of it; the Python tests and the firmware's C tests
both read it (``tests/device/test_wire_vectors.py``, ``firmware/tests/``). Regenerate it
with ``python -m device.serial.vectors > docs/wire-vectors.txt``; a test fails when the file
and this module disagree.

Line format (fields separated by one space; ``#`` starts a comment line)::

    NAME HEX frame VERSION TYPE SEQ BODY_HEX fit|misfit
    NAME HEX error crc|version|length|cobs

``frame``: the frame decodes (COBS, length, CRC, version) to protocol VERSION, message
TYPE (decimal) with sequence number SEQ and the body bytes; ``fit`` when the body has a
layout its type has in that version (docs/wire-protocol.md §1b: before the growth rule
exactly; from it on at least the published length, a command's unknown tail zero; counted
arrays whose count matches; ranges are not judged), ``misfit`` when it does not (a device
answers ``ACK(BAD_MESSAGE)``; an ESTOP stops all the same). ``error``: the frame is
discarded, for the reason given, checked in this order: an encoded frame longer than any
valid one (length), COBS, payload length, CRC, version (an ESTOP is never discarded for its
version: §3).
"""

from __future__ import annotations

import struct
import sys
import zlib

from . import contract as C
from . import messages as M
from .framing import MAX_PAYLOAD, FramingError, cobs_encode, decode_payload, encode_frame

__all__ = ["vectors", "expectation", "render"]


def _examples() -> list[tuple[str, M.Message]]:
    """One example of every message type, with values that exercise signs and zeros."""
    return [
        ("hello", M.Hello(1)),
        ("heartbeat", M.Heartbeat()),
        ("ping", M.Ping(0xDEADBEEF)),
        ("scene_begin", M.SceneBegin(7, 2, -1200, 680.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 12, 200,
                                     2, 0.8)),
        ("scene_velocities", M.SceneVelocities(7, (0.05, 0.11, -0.2))),
        ("scene_chunk", M.SceneChunk(7, 0, 5, (0, 1, -1, 32767, -32768))),
        ("scene_support", M.SceneSupport(7, 350.0, 3.0)),
        ("scene_commit", M.SceneCommit(7, 0x1234ABCD)),
        ("home", M.Home(5)),
        ("start_window", M.StartWindow(7, 5000, 30000, 1)),
        ("stop_window", M.StopWindow()),
        ("play_chunk", M.PlayChunk(0, 3, (100, -100, 0))),
        ("play_start", M.PlayStart(3, 10000)),
        ("set_limit", M.SetLimit(1400)),
        ("estop", M.EStop()),
        ("clear_fault", M.ClearFault()),
        ("zero", M.Zero()),
        ("trace_request", M.TraceRequest(9, 2, 0, 250)),
        ("ack", M.Ack(41, M.Status.BAD_STATE)),
        ("hello_ack", M.HelloAck(1, 10000, 1400, 2150, 55000, 100, 10000, 490333,
                                 b"hapticlab reference".ljust(32, b"\0"),
                                 b"SN-0001".ljust(16, b"\0"), b"1.0.0".ljust(16, b"\0"))),
        ("pong", M.Pong(0xDEADBEEF)),
        ("contact", M.Contact(9, 12345, -110000)),
        ("saturation", M.Saturation(9, 100, 150, 1_650_000)),
        ("fault", M.Fault(M.FaultCode.ESTOP, 2**40 + 5)),
        ("status", M.StatusReport(2**33, M.State.HOMED, -52000, 0)),
        ("window_done", M.WindowDone(9, 2**35, 50000, -1, 8, 1, 0, M.FaultCode.ESTOP)),
        ("trace_block", M.TraceBlock(9, 1, 0, 3, (0.0, -1.5, 3.25))),
        ("position", M.Position(9, 777, -5000)),
        # version 2
        ("trace_config", M.TraceConfig(0x7F, 4)),
        ("limits", M.Limits(16384, 16384, 1024, 0x7F, 100, 100_000, 0, 0, 3,
                                      1_200_000)),
        ("trace_chunk", M.TraceChunk(9, 0x05, 40, 2, (0.25, -1.0, 0.5, 2.0))),
        ("trace_lost", M.TraceLost(9, 1024, 35)),
        ("link_query", M.LinkQuery(1)),
        ("link_report", M.LinkReport(2_500_000, 1234, 2, 131_500, 100,
                                     (0,) * 12 + (40, 900, 55) + (0,) * 48 + (1,))),
    ]


#: the examples sent in version-1 frames (HELLO, as it must, and version 1's own); the
#: rest travel in the newest version
_V1 = {"hello", "trace_request", "trace_block"}


def _raw(version: int, mtype: int, seq: int, body: bytes, crc_xor: int = 0) -> bytes:
    payload = struct.pack("<BBH", version, mtype, seq) + body
    payload += struct.pack("<I", (zlib.crc32(payload) ^ crc_xor) & 0xFFFFFFFF)
    return cobs_encode(payload)


def vectors() -> list[tuple[str, bytes]]:
    """(name, encoded frame without its delimiter) of every vector, in file order."""
    out = [(name, M.encode(m, 100 + i, 1 if name in _V1 else C.PROTOCOL)[:-1])
           for i, (name, m) in enumerate(_examples())]
    # the growth rule (docs §1b): version 2 as published; a longer report and a command
    # whose unknown tail is zero fit, one that asks for more does not, nor a short body
    lim = dict(_examples())["limits"]
    out.append(("limits_v2", M.encode(lim, 200, 2)[:-1]))
    out.append(("limits_v2_as_v3", encode_frame(lim.TYPE, 201, lim.body(), 2)[:-1]))
    out.append(("link_report_v2", M.encode(dict(_examples())["link_report"], 202, 2)[:-1]))
    out.append(("limits_longer", encode_frame(lim.TYPE, 203, lim.body() + b"\x07\0\0\0",
                                              C.PROTOCOL)[:-1]))
    first = C.min_size(C.BY_NAME["LIMITS"], C.PROTOCOL)  # as version 3 was first published
    out.append(("limits_as_published", encode_frame(lim.TYPE, 209, lim.body()[:first],
                                                    C.PROTOCOL)[:-1]))
    out.append(("limits_short", encode_frame(lim.TYPE, 204, lim.body()[:first - 1],
                                             C.PROTOCOL)[:-1]))
    home = M.Home(20_000).body()
    out.append(("home_tail_zero", encode_frame(0x20, 205, home + b"\0\0", C.PROTOCOL)[:-1]))
    out.append(("home_tail_set", encode_frame(0x20, 206, home + b"\0\x01", C.PROTOCOL)[:-1]))
    out.append(("home_v2_longer", encode_frame(0x20, 207, home + b"\0\0", 2)[:-1]))
    # an ESTOP in a frame of a version nobody speaks: decoded (never discarded), acted on
    out.append(("estop_version_9", _raw(9, 0x30, 208, b"")))
    # COBS past 254 bytes: a long run of non-zero bytes, zeros at the edges, and the most
    # items a frame holds (payload 1,024 bytes)
    ramp = tuple(((i % 200) + 1) * 37 for i in range(300))
    out.append(("cobs_run_over_254", encode_frame(0x12, 1, M.SceneChunk(1, 0, len(ramp), ramp)
                                                                    .body())
                [:-1]))
    full = tuple((i * 7919) % 65536 - 32768 for i in range((MAX_PAYLOAD - 4 - 8 - 4) // 2))
    out.append(("cobs_max_payload", encode_frame(0x12, 2, M.SceneChunk(2, 0, len(full), full)
                                                                   .body())
                [:-1]))
    exactly = bytes(range(1, 251))  # 4-byte header + 250 + CRC: blocks of exactly 254
    out.append(("cobs_block_of_254", _raw(1, 0x7F, 0x0101, exactly)))
    out.append(("zeros_everywhere", _raw(1, 0x03, 0, b"\0\0\0\0")))
    # what a receiver must discard
    out.append(("error_crc", _raw(1, 0x03, 5, struct.pack("<I", 1), crc_xor=0x00010000)))
    out.append(("error_version", _raw(C.PROTOCOL + 1, 0x03, 5, struct.pack("<I", 1))))
    out.append(("error_version_0", _raw(0, 0x03, 5, struct.pack("<I", 1))))
    out.append(("error_short", cobs_encode(b"\x01\x03\x05")))
    out.append(("error_long_payload", _raw(1, 0x12, 3, bytes(MAX_PAYLOAD - 7))))
    out.append(("error_cobs_overrun", bytes([0x09, 0x01, 0x02])))
    out.append(("error_encoded_too_long", bytes([0x01]) * (MAX_PAYLOAD + MAX_PAYLOAD // 254 + 3)))
    # frames that decode but whose body does not fit the type
    out.append(("misfit_hello_long", encode_frame(0x01, 7, b"\x01\x02")[:-1]))
    out.append(("misfit_chunk_odd", encode_frame(0x12, 8, b"\x01\0\0\0\0\0\x01\0\xff")[:-1]))
    out.append(("misfit_unknown_type", encode_frame(0x7E, 9, b"")[:-1]))
    out.append(("misfit_chunk_count", encode_frame(0x97, 10, M.TraceChunk(
        1, 0x07, 0, 2, (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)).body()[:-4], C.PROTOCOL)[:-1]))
    return out


def expectation(encoded: bytes) -> str:
    """What the Python implementation makes of ``encoded`` (the file's last fields)."""
    try:
        frame = decode_payload(encoded)
    except FramingError as exc:
        return f"error {exc.kind}"
    try:
        M.decode(frame)
        fit = "fit"
    except FramingError:
        fit = "misfit"
    return f"frame {frame.version} {frame.type} {frame.seq} {frame.body.hex() or '-'} {fit}"


def render() -> str:
    lines = [f"# hapticlab wire protocol test vectors, versions 1 to {C.PROTOCOL} "
             "(device/serial/vectors.py; format in",
             "# its docstring). NAME HEX frame VERSION TYPE SEQ BODY_HEX fit|misfit, or",
             "# NAME HEX error KIND. HEX is the frame on the wire without its 0x00 delimiter;",
             "# BODY_HEX '-' is an empty body."]
    lines += [f"{name} {enc.hex()} {expectation(enc)}" for name, enc in vectors()]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # pragma: no cover
    sys.stdout.write(render())
