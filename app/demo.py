"""``make demo`` until the whole-study dry run exists: one simulated tap window per sample."""

from __future__ import annotations

import time

import numpy as np

__all__ = ["run_demo"]


def run_demo(seed: int = 1) -> int:
    """Run one 5-s simulated tapping window on each realism sample and print a summary."""
    from rich.console import Console
    from rich.table import Table

    from device import open_device
    from protocols import load_protocol

    console = Console()
    protocol = load_protocol("realism")
    table = Table(title=f"one simulated 5-s tap window per sample (sim device, seed {seed})")
    for col in ("sample", "kind", "taps", "v [m/s]", "sat.", "I peak [A]", "a peak [g]"):
        table.add_column(col, no_wrap=True)
    t0 = time.perf_counter()
    with open_device("sim", seed=seed) as dev:
        for sample in protocol.samples.values():
            scene = sample.scene
            if scene.kind == "library":
                console.print(f"[dim]{sample.id}: acceleration-matched library from "
                              f"{scene.transient.source} (built on first use, then cached)[/]")
            dev.load_scene(scene)
            dev.home()
            r = dev.run_window(protocol.window.duration)
            v = r.velocities
            table.add_row(sample.id, scene.kind, str(len(v)),
                          f"{v.mean():.3f}±{v.std(ddof=1) if len(v) > 1 else 0:.3f}",
                          str(len(r.saturations)), f"{r.peak_current:.2f}",
                          f"{np.max(np.abs(r.traces['accel'])) / 9.80665:.1f}")
    console.print(table)
    console.print(f"simulated {len(protocol.samples)} samples in "
                  f"{time.perf_counter() - t0:.1f} s")
    return 0
