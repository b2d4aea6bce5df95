"""``make demo`` until the whole-study dry run exists: one simulated tap window per sample."""

from __future__ import annotations

import time
import tomllib
from importlib import resources

import numpy as np

__all__ = ["run_demo"]


def run_demo(seed: int = 1) -> int:
    """Run one 5-s simulated tapping window on each realism sample and print a summary."""
    from rich.console import Console
    from rich.table import Table

    from device import SceneError, open_device
    from device.scene import Scene

    console = Console()
    text = resources.files("protocols").joinpath("realism.toml").read_text(encoding="utf-8")
    samples = tomllib.loads(text)["samples"]
    table = Table(title=f"one simulated 5-s tap window per sample (sim device, seed {seed})")
    for col in ("sample", "kind", "taps", "v [m/s]", "sat.", "I peak [A]", "a peak [g]"):
        table.add_column(col, no_wrap=True)
    skipped: list[str] = []
    t0 = time.perf_counter()
    with open_device("sim", seed=seed) as dev:
        for s in samples:
            try:
                scene = Scene.from_dict({"name": s["id"], **s["scene"]},
                                        where=f"realism.toml sample '{s['id']}'")
            except SceneError as exc:
                skipped.append(f"{s['id']}: not simulated: {exc}")
                continue
            dev.load_scene(scene)
            dev.home()
            r = dev.run_window(5.0)
            v = r.velocities
            table.add_row(scene.name, scene.kind, str(len(v)),
                          f"{v.mean():.3f}±{v.std(ddof=1) if len(v) > 1 else 0:.3f}",
                          str(len(r.saturations)), f"{r.peak_current:.2f}",
                          f"{np.max(np.abs(r.traces['accel'])) / 9.80665:.1f}")
    console.print(table)
    for line in skipped:
        console.print(f"[yellow]{line}[/]")
    elapsed = time.perf_counter() - t0
    console.print(f"simulated {len(samples) - len(skipped)} samples in {elapsed:.1f} s")
    return 0
