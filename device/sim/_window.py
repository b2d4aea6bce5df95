"""A simulated window's per-tick arrays (:class:`Buffers`, grown as the window runs, with
the hand's input beside them) and its traces taken piece by piece as a streaming device sends
them (:class:`TracePieces`); private to :mod:`device.sim`."""

from __future__ import annotations

import numpy as np

from . import kernel as K

__all__ = ["Buffers", "TracePieces", "runs", "STREAM_TICKS", "PULL_AHEAD"]

#: live mode with a trace sink: new ticks are handed over once this many have accumulated
STREAM_TICKS = 200


class TracePieces:
    """A window's traces taken in order, piece by piece, as a streaming device sends them;
    :meth:`joined` gives the whole (taking what is left)."""

    def __init__(self, dev, buf: Buffers):
        self.dev, self.buf = dev, buf
        self.done = 0
        self.pieces: list[dict[str, np.ndarray]] = []

    def take(self, n: int) -> dict[str, np.ndarray]:
        piece = self.dev._traces(self.buf, self.done, n)
        self.pieces.append(piece)
        self.done = n
        return piece

    def joined(self, n: int) -> dict[str, np.ndarray]:
        if n > self.done or not self.pieces:
            self.take(n)
        if len(self.pieces) == 1:
            return dict(self.pieces[0])
        return {k: np.concatenate([p[k] for p in self.pieces]) for k in self.pieces[0]}


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the True runs of a boolean array."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))



#: ticks of the hand's pull computed ahead of the servo at a time (1 s at 10 kHz)
PULL_AHEAD = 10_000


class Buffers:
    """Growable per-tick arrays of a window, with the hand input computed alongside."""

    def __init__(self, capacity: int, plan, gains: tuple[float, float, float], dt: float):
        self.plan, self.gains, self.dt = plan, gains, dt
        self.n = 0
        self.out = np.zeros((K.N_OUT, 0))
        self.flags = np.zeros(0, dtype=np.int64)
        self.u_hand = np.zeros(1)
        self.pulled = 0  # ticks whose hand pull is computed
        self._grow(capacity)

    pos = property(lambda self: self.out[K.OUT_POS])
    fcmd = property(lambda self: self.out[K.OUT_FCMD])
    fout = property(lambda self: self.out[K.OUT_FOUT])
    cur = property(lambda self: self.out[K.OUT_CUR])
    acc = property(lambda self: self.out[K.OUT_ACC])
    z2 = property(lambda self: self.out[K.OUT_Z2])
    v2 = property(lambda self: self.out[K.OUT_V2])
    a2 = property(lambda self: self.out[K.OUT_A2])

    def ensure(self, n: int) -> None:
        """Room for ticks [0, n) and the hand's pull computed up to tick n (and one beyond,
        for its slope over the last tick). The pull is computed as the ticks come, never
        ahead: for a window of 20 minutes all at once it held the interpreter for seconds,
        and the emulator's serve loop fell silent meanwhile (issue 53 item 2)."""
        if n > self.n:
            self._grow(max(n, 2 * self.n))
        if n + 1 > self.pulled:
            start, end = self.pulled, min(self.n + 1, max(n + 1, self.pulled + PULL_AHEAD))
            zr, vr, ar = self.plan.reference(np.arange(start, end) * self.dt)
            kz, kv, ka = self.gains
            self.u_hand[start:end] = kz * zr + kv * vr + ka * ar
            self.pulled = end

    def _grow(self, new: int) -> None:
        """Room for ``new`` ticks (zeros: memory the window does not reach is never touched)."""
        if new > self.n:
            out = np.zeros((K.N_OUT, new))
            out[:, : self.n] = self.out[:, : self.n]
            self.out = out
            f = np.zeros(new, dtype=np.int64)
            f[: self.n] = self.flags[: self.n]
            self.flags = f
            u = np.zeros(new + 1)
            u[: self.pulled] = self.u_hand[: self.pulled]
            self.u_hand = u
            self.n = new
