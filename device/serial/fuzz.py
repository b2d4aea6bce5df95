"""Mutation fuzzing of the framing layer (used by the tests and ``hapticlab bench link --fuzz``).

A stream of valid frames of random messages is corrupted — bit flips, truncations,
inserted bytes, garbage between frames — and fed to :class:`FrameDecoder`. Every frame
the decoder accepts must be one of the frames sent, byte for byte; and after each
corrupted frame the next intact one must be decoded (resynchronisation within one frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import messages as M
from .framing import FrameDecoder

__all__ = ["FuzzReport", "fuzz"]


@dataclass
class FuzzReport:
    frames: int
    mutated: int
    accepted_corrupt: int
    intact_lost: int  #: clean frames (not mutated, no garbage before) that did not decode
    decoded: int

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def _random_message(rng: np.random.Generator) -> M.Message:
    kind = int(rng.integers(0, 6))
    if kind == 0:
        return M.Contact(int(rng.integers(0, 65536)), int(rng.integers(0, 2**32)),
                         int(rng.integers(-2**31, 2**31)))
    if kind == 1:
        n = int(rng.integers(0, 40))
        return M.TraceBlock(1, int(rng.integers(0, 10)), int(rng.integers(0, 10**6)), n,
                            tuple(float(np.float32(x)) for x in rng.normal(size=n)))
    if kind == 2:
        n = int(rng.integers(0, 60))
        return M.SceneChunk(3, int(rng.integers(0, 10**5)), n,
                            tuple(int(x) for x in rng.integers(-32768, 32768, n)))
    if kind == 3:
        return M.StatusReport(int(rng.integers(0, 2**62)), int(rng.integers(0, 5)),
                              int(rng.integers(-10_000, 10_000)), 0)
    if kind == 4:
        return M.Ack(int(rng.integers(0, 65536)), int(rng.integers(0, 7)))
    return M.Heartbeat()


def _mutate(frame: bytes, rng: np.random.Generator) -> bytes:
    b = bytearray(frame[:-1])  # keep the delimiter out of the mutation, add it back
    op = int(rng.integers(0, 4))
    if op == 0 and b:  # flip 1–3 bits
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(0, len(b)))
            b[i] ^= 1 << int(rng.integers(0, 8))
    elif op == 1 and len(b) > 1:  # truncate
        del b[int(rng.integers(1, len(b))):]
    elif op == 2:  # insert bytes
        i = int(rng.integers(0, len(b) + 1))
        b[i:i] = bytes(rng.integers(1, 256, int(rng.integers(1, 4))).astype(np.uint8))
    else:  # overwrite a byte
        if b:
            b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
    return bytes(b) + b"\x00"


def fuzz(n: int, seed: int = 0, p_mutate: float = 0.5, p_garbage: float = 0.2) -> FuzzReport:
    """Send ``n`` frames, mutate about half, sprinkle garbage; report what got through."""
    rng = np.random.default_rng(seed)
    dec = FrameDecoder()
    sent: set[bytes] = set()
    accepted_corrupt = intact_lost = mutated = decoded = 0
    for i in range(n):
        msg = _random_message(rng)
        frame = M.encode(msg, i & 0xFFFF)
        intact = rng.random() >= p_mutate
        wire = frame if intact else _mutate(frame, rng)
        mutated += not intact
        garbage = rng.random() < p_garbage
        if garbage:  # garbage (possibly with zeros) right before the frame: it takes the
            # frame with it unless it ends in a zero; the *next* frame must decode
            wire = bytes(rng.integers(0, 256, int(rng.integers(1, 20))).astype(np.uint8)) + wire
        out = dec.feed(wire)
        decoded += len(out)
        got = [M.encode(M.decode(f), f.seq) if f.type in M.MESSAGES else None for f in out]
        for g in got:
            if g is None or g != frame:
                accepted_corrupt += 1
        if intact and not garbage and frame not in got:
            intact_lost += 1  # a clean frame after any corruption must decode
        sent.add(frame)
    return FuzzReport(n, mutated, accepted_corrupt, intact_lost, decoded)
