"""Frames on the wire: COBS-encoded payloads with a CRC-32, delimited by 0x00.

    payload = version (u8) · type (u8) · seq (u16 LE) · body · crc32 (u32 LE)
    frame   = COBS(payload) · 0x00

The CRC is CRC-32/ISO-HDLC (the zlib/Ethernet CRC: polynomial 0x04C11DB7 reflected,
initial value and final XOR 0xFFFFFFFF) over version..body. See docs/wire-protocol.md.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

from .contract import PROTOCOL

__all__ = ["cobs_encode", "cobs_decode", "encode_frame", "decode_payload", "FrameDecoder",
           "FramingError", "PROTOCOL_VERSION", "MAX_PAYLOAD", "Frame"]

#: the newest version this host speaks (the contract states it); frames of every version
#: from PROTOCOL_MIN up are decoded (a HELLO always travels in version 1 so that any
#: device reads it), and an ESTOP in a frame of any version (docs §3)
PROTOCOL_VERSION = PROTOCOL
PROTOCOL_MIN = 1
_ESTOP = 0x30
MAX_PAYLOAD = 1024  # bytes before COBS, CRC included
_HEAD = struct.Struct("<BBH")
_CRC = struct.Struct("<I")


class FramingError(ValueError):
    """A frame could not be decoded; ``kind`` says why: ``cobs``, ``length``, ``crc``,
    ``version`` (or ``body`` for a message whose body misfits its type)."""

    def __init__(self, message: str, kind: str = "body"):
        super().__init__(message)
        self.kind = kind


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the result contains no zero byte."""
    out = bytearray()
    for run in bytes(data).split(b"\x00"):  # the runs between zeros, each ended by one
        while len(run) >= 254:  # a full block: code 255, no zero implied
            out.append(255)
            out += run[:254]
            run = run[254:]
        out.append(len(run) + 1)
        out += run
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises FramingError on malformed input."""
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise FramingError("zero byte inside a COBS frame", "cobs")
        end = i + code
        if end > n:
            raise FramingError("COBS block runs past the end of the frame", "cobs")
        block = data[i + 1: end]
        if 0 in block:
            raise FramingError("zero byte inside a COBS block", "cobs")
        out += block
        i = end
        if code < 255 and i < n:
            out.append(0)
    return bytes(out)


@dataclass(frozen=True)
class Frame:
    """A decoded frame: message type, sequence number and body bytes."""

    type: int
    seq: int
    body: bytes
    version: int = 1


def encode_frame(mtype: int, seq: int, body: bytes = b"", version: int = 1) -> bytes:
    """COBS-encoded, delimited frame for (type, seq, body) in protocol ``version``."""
    payload = _HEAD.pack(version, mtype, seq & 0xFFFF) + body
    payload += _CRC.pack(zlib.crc32(payload) & 0xFFFFFFFF)
    if len(payload) > MAX_PAYLOAD:
        raise FramingError(f"payload of {len(payload)} bytes exceeds the maximum {MAX_PAYLOAD}",
                           "length")
    return cobs_encode(payload) + b"\x00"


def decode_payload(encoded: bytes) -> Frame:
    """Decode one frame (without its delimiter): COBS, length, CRC, version."""
    if len(encoded) > MAX_PAYLOAD + MAX_PAYLOAD // 254 + 2:
        raise FramingError(f"frame of {len(encoded)} bytes is longer than any valid frame",
                           "length")
    payload = cobs_decode(encoded)
    if len(payload) < _HEAD.size + _CRC.size:
        raise FramingError(f"frame of {len(payload)} bytes is shorter than header + CRC",
                           "length")
    if len(payload) > MAX_PAYLOAD:
        raise FramingError(f"payload of {len(payload)} bytes exceeds the maximum {MAX_PAYLOAD}",
                           "length")
    body, (crc,) = payload[:-4], _CRC.unpack(payload[-4:])
    if zlib.crc32(body) & 0xFFFFFFFF != crc:
        raise FramingError("CRC mismatch", "crc")
    version, mtype, seq = _HEAD.unpack(body[:4])
    if not PROTOCOL_MIN <= version <= PROTOCOL_VERSION and mtype != _ESTOP:
        raise FramingError(f"protocol version {version}, expected {PROTOCOL_MIN}–"
                           f"{PROTOCOL_VERSION}", "version")
    return Frame(mtype, seq, body[4:], version)


class FrameDecoder:
    """Streaming decoder: feed bytes, get frames; bad frames are counted and skipped.

    Resynchronisation is at the next 0x00 delimiter: after garbage or a corrupt frame,
    the first complete frame that follows is decoded.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.frames_ok = 0
        self.errors: dict[str, int] = {"crc": 0, "cobs": 0, "length": 0, "version": 0,
                                       "body": 0}  # body: a frame whose body misfits its type

    def feed(self, data: bytes) -> list[Frame]:
        out = []
        self._buf += data
        while True:
            k = self._buf.find(0)
            if k < 0:
                if len(self._buf) > 4 * MAX_PAYLOAD:  # no delimiter in sight: drop junk
                    self._buf.clear()
                    self.errors["length"] += 1
                return out
            chunk = bytes(self._buf[:k])
            del self._buf[: k + 1]
            if not chunk:
                continue
            try:
                out.append(decode_payload(chunk))
                self.frames_ok += 1
            except FramingError as exc:
                self.errors[exc.kind if exc.kind in self.errors else "length"] += 1
