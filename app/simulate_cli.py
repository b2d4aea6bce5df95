"""``hapticlab simulate``: whole sessions with simulated participants, headless.

Each participant's session goes through the same path as ``hapticlab run --ui none
--responder simulated``: engine, runner, recorder and device backend. Participant k of a
run with seed S gets the session seed drawn from SeedSequence([S, k]), so a study is
reproduced from S alone (each session.json records its own seed as usual).
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time
from contextlib import contextmanager

import numpy as np

__all__ = ["simulate", "add_parser", "session_seed"]


def session_seed(study_seed: int, k: int) -> int:
    """Session seed of participant ``k`` (1-based) of a simulated study."""
    return int(np.random.SeedSequence([study_seed, k]).generate_state(1, np.uint32)[0])


@contextmanager
def _device_spec(spec: str, speed: float = 1.0):
    """``serial:emulator`` starts a device emulator on a pty for the run, paced at ``speed``
    × real time."""
    if spec != "serial:emulator":
        yield spec
        return
    proc = subprocess.Popen([sys.executable, "-m", "app", "device", "emulate", "--speed",
                             repr(float(speed))],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        port = proc.stdout.readline().strip()
        if not port:
            raise ValueError("the device emulator did not start")
        yield f"serial:{port}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def simulate(args: argparse.Namespace) -> int:
    from app.session_cli import run

    if args.participants < 1:
        raise ValueError(f"--participants must be at least 1, got {args.participants}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    if not (args.speed > 0 and math.isfinite(args.speed)):
        raise ValueError(f"--speed must be a finite number > 0, got {args.speed}")
    t0 = time.perf_counter()
    with _device_spec(args.device, args.speed) as spec:
        for k in range(1, args.participants + 1):
            pid = f"{args.prefix}{k:02d}"
            run_args = argparse.Namespace(
                protocol=args.protocol, participant=pid, device=spec,
                seed=session_seed(args.seed, k), data=args.data, ui="none",
                responder="simulated", no_audio=True, row=None, traces=args.traces,
                fullscreen=False, group=args.group, quiet=True)
            rc = run(run_args)
            if rc != 0:
                return rc
            print(f"  {args.protocol}: participant {k}/{args.participants} done "
                  f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    return 0


def add_parser(sub, func) -> None:
    p = sub.add_parser("simulate", help="run a whole study with simulated participants")
    p.add_argument("protocol", help="realism, factorial, identification, or a protocol file")
    p.add_argument("--participants", type=int, default=9)
    p.add_argument("--seed", type=int, default=0, help="study seed (session seeds derive from it)")
    p.add_argument("--data", default="data", help="data folder (default ./data)")
    p.add_argument("--device", default="sim",
                   help="sim, sim:RATE, serial:PORT or serial:emulator (paced by --speed)")
    p.add_argument("--speed", type=float, default=1.0,
                   help="serial:emulator only: device seconds per wall second (default 1)")
    p.add_argument("--traces", choices=("full", "contacts", "none"), default="contacts")
    p.add_argument("--prefix", default="sim", help="participant ids are PREFIX01, PREFIX02, …")
    p.add_argument("--group", default="", help="group label of these participants")
    p.set_defaults(func=func)
