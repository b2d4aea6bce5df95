"""Figures (matplotlib, PNG and SVG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["save_all"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out: Path, name: str) -> list[str]:
    paths = []
    for ext in ("png", "svg"):
        p = out / f"{name}.{ext}"
        fig.savefig(p, dpi=110, bbox_inches="tight", metadata={"Date": None} if ext == "svg"
                    else None)
        paths.append(p.name)
    _plt().close(fig)
    return paths


def realism_means(r: dict, out: Path) -> list[str]:
    plt = _plt()
    s = pd.DataFrame(r["samples"])
    fig, ax = plt.subplots(figsize=(8, 4))
    x = np.arange(len(s))
    ax.errorbar(x, s["mean"], yerr=[s["mean"] - s["ci_low"], s["ci_high"] - s["mean"]],
                fmt="o", capsize=4)
    ax.set_xticks(x, s["sample"], rotation=40, ha="right")
    ax.set_ylabel("realism rating (mean ± 95 % CI)")
    ax.set_title(f"Realism of the samples (n = {r['n_subjects']} participants)")
    return _save(fig, out, "realism_means")


def realism_pmatrix(r: dict, out: Path) -> list[str]:
    plt = _plt()
    order = [x["sample"] for x in r["samples"]]
    m = pd.DataFrame(np.nan, index=order, columns=order)
    for row in r["pairwise"].itertuples():
        m.loc[row.A, row.B] = m.loc[row.B, row.A] = row.p_holm
    fig, ax = plt.subplots(figsize=(7, 6))
    im = ax.imshow(m.to_numpy(dtype=float), vmin=0, vmax=1, cmap="viridis")
    ax.set_xticks(range(len(order)), order, rotation=60, ha="right")
    ax.set_yticks(range(len(order)), order)
    fig.colorbar(im, label="Holm-adjusted p (paired t-test)")
    ax.set_title("Which samples differ")
    return _save(fig, out, "realism_pvalues")


def factorial_interactions(f: dict, out: Path) -> list[str]:
    plt = _plt()
    files = []
    for material, res in f.items():
        sets = res["sets"]
        fig, axes = plt.subplots(1, 3, figsize=(11, 3.4), sharey=True)
        pairs = [("frequency", "decay"), ("frequency", "slope"), ("decay", "slope")]
        for ax, (a, b) in zip(axes, pairs, strict=True):
            for lvl, g in sets.groupby(b):
                mm = g.groupby(a)["mean"].mean().reindex(["low", "high"])
                ax.plot(["low", "high"], mm.to_numpy(), "o-", label=f"{b} {lvl}")
            ax.set_xlabel(a)
            ax.legend(fontsize=8)
        axes[0].set_ylabel("mean rating (z)")
        fig.suptitle(f"{material}: interactions (most significant: {res['most_significant']})")
        files += _save(fig, out, f"factorial_{material}")
    return files


def confusion(i: dict, out: Path) -> list[str]:
    plt = _plt()
    c = i["confusion"]
    fig, ax = plt.subplots(figsize=(4.5, 4))
    ax.imshow(c.to_numpy(), cmap="Blues")
    for (y, x), v in np.ndenumerate(c.to_numpy()):
        ax.text(x, y, str(v), ha="center", va="center")
    ax.set_xticks(range(len(c.columns)), c.columns)
    ax.set_yticks(range(len(c.index)), c.index)
    ax.set_xlabel("answered")
    ax.set_ylabel("presented")
    ax.set_title("Identification: confusion")
    return _save(fig, out, "identification_confusion")


def accel_traces(data: pd.DataFrame, out: Path, speed: float = 0.11) -> list[str]:
    """Acceleration after contact per sample, for the tap closest to a common speed."""
    plt = _plt()
    d = data[(data["protocol"] == "realism") & data["valid"] & (data["trace_file"] != "")]
    picked = []
    for sample, g in d.groupby("sample"):
        best = None
        for row in g.itertuples():
            path = Path(row.session_dir) / row.trace_file
            if not path.exists() or "*" in row.trace_file:
                continue
            with np.load(path) as z:
                if not len(z["contacts_v"]):
                    continue
                k = int(np.argmin(np.abs(z["contacts_v"] - speed)))
                err = abs(z["contacts_v"][k] - speed)
                if best is None or err < best[0]:
                    rate, t0 = float(z["rate_hz"]), float(z["t0"])
                    idx = z["sample_index"] if "sample_index" in z else np.arange(
                        len(z["accel_counts"]))
                    i = int(round((z["contacts_t"][k] - t0) * rate))
                    sel = (idx >= i) & (idx < i + int(0.1 * rate))
                    a = z["accel_counts"][sel] * float(z["accel_lsb"])
                    best = (err, a, float(z["contacts_v"][k]), rate)
        if best is not None:
            picked.append((str(sample), *best[1:]))
    # one panel per sample on a shared scale: 11 overlaid traces hide each other
    cols = 4
    rows = max(1, -(-len(picked) // cols))
    fig, axes = plt.subplots(rows, cols, figsize=(10, 1.9 * rows + 0.8), sharex=True,
                             sharey=True, squeeze=False)
    for ax, (sample, a, v, rate) in zip(axes.flat, picked, strict=False):
        ax.plot(np.arange(len(a)) / rate * 1e3, a / v * speed, lw=0.7, color="C0")
        ax.set_title(f"{sample} ({v:.3f} m/s)", fontsize=8)
    for ax in axes.flat[len(picked):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("ms after contact", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("m/s²", fontsize=8)
    fig.suptitle(f"Contact acceleration per sample, scaled to {speed} m/s incoming speed",
                 fontsize=10)
    fig.tight_layout()
    return _save(fig, out, "accel_traces")


def session_length(realism: dict, out: Path) -> list[str]:
    """Power of a 1-point contrast and CI half-width against participants, per repetitions."""
    plt = _plt()
    t = realism["session_length"]["table"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    for r, g in t.groupby("reps"):
        a1.plot(g["subjects"], g["power"], marker="o", ms=3, label=f"{r} rep.")
        a2.plot(g["subjects"], g["ci_halfwidth"], marker="o", ms=3, label=f"{r} rep.")
    a1.set_xlabel("participants")
    a1.set_ylabel("power (1-point difference, Bonferroni)")
    a1.set_ylim(0, 1)
    a2.set_xlabel("participants")
    a2.set_ylabel("95 % CI half-width of a mean [points]")
    a1.legend(fontsize=7)
    fig.suptitle("Session length against power and precision (variances from these data)",
                 fontsize=10)
    fig.tight_layout()
    return _save(fig, out, "session_length")


def save_all(data, results: dict, out: Path) -> list[str]:
    files = []
    if isinstance(results.get("realism"), dict):
        files += realism_means(results["realism"], out)
        files += session_length(results["realism"], out)
        files += realism_pmatrix(results["realism"], out)
        files += accel_traces(data, out)
    if isinstance(results.get("factorial"), dict):
        files += factorial_interactions(results["factorial"], out)
    if isinstance(results.get("identification"), dict) and \
            results["identification"].get("confusion") is not None:
        files += confusion(results["identification"], out)
    return files
