"""Figures (matplotlib, PNG and SVG)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pandas as pd

from .session_format import inside_session

__all__ = ["rating_means", "rating_pmatrix", "factorial_interactions", "confusion", "accel_traces",
           "session_length", "figure_prefix", "staircases", "psychometric"]


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


def _name(a: dict) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in a["id"].replace("/", "-"))


def figure_prefix(a: dict) -> str:
    """What every figure file of analysis ``a`` starts with."""
    return _name(a) + "_"


def rating_means(a: dict, out: Path) -> list[str]:
    plt = _plt()
    r = a["result"]
    s = pd.DataFrame(r["samples"])
    fig, ax = plt.subplots(figsize=(max(5, 0.7 * len(s) + 2), 4))
    x = np.arange(len(s))
    ax.errorbar(x, s["mean"], yerr=[s["mean"] - s["ci_low"], s["ci_high"] - s["mean"]],
                fmt="o", capsize=4)
    ax.set_xticks(x, s["sample"], rotation=40, ha="right")
    scale = a.get("scale")
    if scale:
        ax.set_ylim(scale["min"] - 0.3, scale["max"] + 0.3)
    letters = r.get("letters") or {}
    for xi, sample in enumerate(s["sample"]):  # the report table's letters, above the axes
        text = letters.get(sample, "")
        if text and len(text) <= 6:
            ax.text(xi, 1.01, text, transform=ax.get_xaxis_transform(), ha="center",
                    va="bottom", fontsize=9)
    ax.set_ylabel("rating (mean ± 95 % CI)")
    ax.set_title(f"{a['id']}: ratings of the samples (n = {r['n_subjects']}; "
                 "samples sharing a letter do not differ, Holm)", pad=18, fontsize=10)
    return _save(fig, out, f"{_name(a)}_means")


def rating_pmatrix(a: dict, out: Path) -> list[str]:
    plt = _plt()
    r = a["result"]
    order = [x["sample"] for x in r["samples"]]
    m = pd.DataFrame(np.nan, index=order, columns=order)
    for row in r["pairwise"].itertuples():
        m.loc[row.A, row.B] = m.loc[row.B, row.A] = row.p_holm
    fig, ax = plt.subplots(figsize=(max(4, 0.5 * len(order) + 2), max(3.5, 0.45 * len(order)
                                                                          + 1.5)))
    from matplotlib.colors import BoundaryNorm, ListedColormap

    # bands, not a continuous map: p = .04 and .06 lie on either side of α and must look so
    bounds = [0, 0.001, 0.01, 0.05, 1.0]
    cmap = ListedColormap(["#08306b", "#2171b5", "#6baed6", "#f0f0f0"]).with_extremes(
        bad="white")
    im = ax.imshow(m.to_numpy(dtype=float), cmap=cmap, norm=BoundaryNorm(bounds, cmap.N))
    ax.set_xticks(range(len(order)), order, rotation=60, ha="right")
    ax.set_yticks(range(len(order)), order)
    bar = fig.colorbar(im, label="Holm-adjusted p (paired t-test)", ticks=[0.0005, 0.005,
                                                                            0.03, 0.5])
    bar.ax.set_yticklabels(["< .001", "< .01", "< .05", "≥ .05 (α)"])
    ax.set_title(f"{a['id']}: which samples differ")
    return _save(fig, out, f"{_name(a)}_pvalues")


def factorial_interactions(a: dict, out: Path) -> list[str]:
    import itertools

    plt = _plt()
    factors = list(a["phase_design"]["within"])
    files = []
    for group, res in a["result"].items():
        sets = res["sets"]
        pairs = list(itertools.combinations(factors, 2)) or [(factors[0], factors[0])]
        fig, axes = plt.subplots(1, len(pairs), figsize=(3.7 * len(pairs), 3.4), sharey=True,
                                 squeeze=False)
        for ax, (f1, f2) in zip(axes[0], pairs, strict=True):
            levels = list(dict.fromkeys(sets.sort_values(f1)[f1]))
            if set(levels) == {"low", "high"}:
                levels = ["low", "high"]
            cells = res.get("cell_means")
            for lvl, g in sets.groupby(f2):
                mm = g.groupby(f1)["mean"].mean().reindex(levels)
                if cells is not None and len(cells):  # 95 % CI over participants
                    per = (cells[cells[f2] == lvl].groupby(["participant", f1])["value"]
                           .mean().unstack(f1).reindex(columns=levels))
                    n = per.notna().sum().to_numpy()
                    half = np.where(n > 1, per.std(ddof=1).to_numpy() / np.sqrt(np.maximum(n, 1))
                                    * _t975(n - 1), 0.0)
                    ax.errorbar(levels, per.mean().to_numpy(), yerr=half, fmt="o-", capsize=3,
                                label=f"{f2} {lvl}")
                else:
                    ax.plot(levels, mm.to_numpy(), "o-", label=f"{f2} {lvl}")
            ax.set_xlabel(f1)
            ax.legend(fontsize=8)
        axes[0][0].set_ylabel("mean rating" + (" (z)" if (a["phase_design"].get("normalize")
                                                          or "none") != "none" else "")
                              + " ± 95 % CI")
        p = float(res["most_significant_p"])
        most = (f"most significant: {res['most_significant']}, p = {p:.3g}" if p < 0.05 else
                f"no factor significant; smallest p = {p:.2g}, {res['most_significant']}")
        fig.suptitle(f"{a['id']} — {group}: interactions ({most})")
        files += _save(fig, out, f"{_name(a)}_{group}")
    return files


def _ink(values: np.ndarray) -> np.ndarray:
    """Text colour per cell of a 'Blues' image of ``values``: white on the dark half, black
    on the light half (black numbers on navy could not be read)."""
    top = float(values.max()) if values.size else 0.0
    return np.where(values > top / 2, "white", "black")


def _t975(df: np.ndarray) -> np.ndarray:
    """The t distribution's 97.5 % quantile for each ``df`` (≥ 1)."""
    from scipy import special

    return special.stdtrit(np.maximum(df, 1), 0.975)


def confusion(a: dict, out: Path) -> list[str]:
    plt = _plt()
    c = a["result"]["confusion"]
    fig, ax = plt.subplots(figsize=(4.5, 4))
    values = c.to_numpy()
    ax.imshow(values, cmap="Blues")
    ink = _ink(values)
    for (y, x), v in np.ndenumerate(values):
        ax.text(x, y, str(v), ha="center", va="center", color=ink[y, x])
    ax.set_xticks(range(len(c.columns)), c.columns)
    ax.set_yticks(range(len(c.index)), c.index)
    ax.set_xlabel("answered")
    ax.set_ylabel("presented")
    ax.set_title(f"{a['id']}: confusion")
    return _save(fig, out, f"{_name(a)}_confusion")


def _tap_near(path: Path, speed: float):
    """(|v − speed|, acceleration [m/s²] 100 ms from contact, v [m/s], rate [Hz]) of the tap
    in a trace file whose incoming speed is nearest ``speed``; None without contacts, or from
    a device without an accelerometer (no ``accel_counts``)."""
    with np.load(path) as z:
        if not len(z["contacts_v"]) or "accel_counts" not in z:
            return None
        k = int(np.argmin(np.abs(z["contacts_v"] - speed)))
        rate, t0 = float(z["rate_hz"]), float(z["t0"])
        idx = z["sample_index"] if "sample_index" in z else np.arange(len(z["accel_counts"]))
        i = int(round((z["contacts_t"][k] - t0) * rate))
        sel = (idx >= i) & (idx < i + int(0.1 * rate))
        acc = z["accel_counts"][sel] * float(z["accel_lsb"])
        return abs(z["contacts_v"][k] - speed), acc, float(z["contacts_v"][k]), rate


#: recordings of a sample searched for the tap nearest the common speed (the first ones, in
#: the order of the rows: 10⁶ rows would otherwise open 10⁶ files for one figure)
TRACES_PER_SAMPLE = 200


def accel_traces(a: dict, data: pd.DataFrame, out: Path, speed: float = 0.11) -> list[str]:
    """Acceleration after contact per sample, for the tap closest to a common speed among
    the sample's first :data:`TRACES_PER_SAMPLE` recordings."""
    plt = _plt()
    d = data[(data["design_key"] == a["design_key"]) & (data["phase"] == a["phase"])
             & data["valid"] & (data["trace_file"].fillna("") != "")]
    picked, skipped = [], []
    for sample, g in d.groupby("sample"):
        best = None
        for row in g.head(TRACES_PER_SAMPLE).itertuples():
            path = Path(row.session_dir) / row.trace_file
            if not path.exists() or "*" in row.trace_file:
                continue
            try:
                inside_session(row.session_dir, row.trace_file)  # not through a link out
                tap = _tap_near(path, speed)
            except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
                skipped.append(str(path))  # a truncated or foreign file: not this figure's
                continue
            if tap is not None and (best is None or tap[0] < best[0]):
                best = tap
        if best is not None:
            picked.append((str(sample), *best[1:]))
    if not picked:
        return []
    # one panel per sample on a shared scale: overlaid traces hide each other
    cols = 4
    rows = max(1, -(-len(picked) // cols))
    fig, axes = plt.subplots(rows, cols, figsize=(10, 1.9 * rows + 0.8), sharex=True,
                             sharey=True, squeeze=False)
    for ax, (sample, acc, v, rate) in zip(axes.flat, picked, strict=False):
        ax.plot(np.arange(len(acc)) / rate * 1e3, acc / v * speed, lw=0.7, color="C0")
        ax.set_title(f"{sample} ({v:.3f} m/s)", fontsize=8)
    for ax in axes.flat[len(picked):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("ms after contact", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("m/s²", fontsize=8)
    note = (f" ({len(skipped)} trace files unreadable or linked out of their session folder "
            "skipped)" if skipped else "")
    fig.suptitle(f"{a['id']}: contact acceleration per sample, scaled to {speed} m/s incoming "
                 f"speed{note}", fontsize=10)
    fig.tight_layout()
    return _save(fig, out, f"{_name(a)}_accel_traces")


def session_length(a: dict, out: Path) -> list[str]:
    """Power of a 1-point contrast and CI half-width against participants, per repetitions."""
    plt = _plt()
    t = a["result"]["session_length"]["table"]
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
    fig.suptitle(f"{a['id']}: session length against power and precision (variances from "
                 "these data)", fontsize=10)
    fig.tight_layout()
    return _save(fig, out, f"{_name(a)}_session_length")


def _track_data(a: dict, data: pd.DataFrame) -> pd.DataFrame:
    from .thresholds import track_rows

    d = data[(data["design_key"] == a["design_key"]) & (data["phase"] == a["phase"])]
    return track_rows(d)


def _per_track(a: dict, data: pd.DataFrame):
    """(result, the phase's trials, its tracks, figure, an axis per track), or None when
    there is nothing to draw."""
    r = a["result"]
    d = _track_data(a, data)
    names = [g["track"] for g in r["group"]]
    if d.empty or not names:
        return None
    fig, axes = _track_axes(_plt(), len(names))
    return r, d, names, fig, axes


def _track_axes(plt, n: int, width: float = 4.2, height: float = 3.2):
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(width * cols, height * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, list(axes.ravel())


def staircases(a: dict, data: pd.DataFrame, out: Path) -> list[str]:
    """Each track's intensity trial by trial: a line per participant, right answers
    filled, wrong ones open, reversals ringed (catch trials left out)."""
    got = _per_track(a, data)
    if got is None:
        return []
    r, d, names, fig, axes = got
    for ax, name in zip(axes, names, strict=False):
        for _pid, g in d[d["track"] == name].groupby("participant", sort=True):
            g = g.reset_index(drop=True)
            proc = g[~g["catch"]]
            n = np.arange(1, len(proc) + 1)
            line, = ax.plot(n, proc["intensity"], lw=0.8, alpha=0.7)
            c = line.get_color()
            right = proc["correct"].to_numpy() == 1
            ax.scatter(n[right], proc["intensity"].to_numpy()[right], s=14, color=c)
            ax.scatter(n[~right], proc["intensity"].to_numpy()[~right], s=14,
                       facecolors="none", edgecolors=c)
            rev = proc["reversal"].to_numpy()
            ax.scatter(n[rev], proc["intensity"].to_numpy()[rev], s=60, facecolors="none",
                       edgecolors="k", linewidths=0.6)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("trial of the track")
        ax.set_ylabel(f"intensity ({r['units']})")
    fig.suptitle(f"{a['id']}: {r['parameter']} ({r['procedure']})", fontsize=10)
    fig.tight_layout()
    return _save(fig, out, figure_prefix(a) + "tracks")


def psychometric(a: dict, data: pd.DataFrame, out: Path) -> list[str]:
    """Per track: proportion correct at each intensity (area ∝ trials there, all
    participants pooled), each participant's maximum-likelihood function (it meets the
    criterion at ``threshold_ml``), each participant's stated threshold — the posterior
    median, which the tables give — as a tick on the criterion with its credible interval,
    and the group's mean of the stated thresholds (dashed): the figure shows the tables'
    numbers, and says which number is which in the caption."""
    from .psychometric import levels

    got = _per_track(a, data)
    if got is None:
        return []
    r, d, names, fig, axes = got
    for ax, name in zip(axes, names, strict=False):
        g = d[d["track"] == name]
        lv = levels(g["intensity"], g["correct"])
        ax.scatter(lv["x"], lv["k"] / lv["n"], s=12 * lv["n"], alpha=0.45, color="0.3",
                   edgecolors="none")
        lo, hi = float(lv["x"].min()), float(lv["x"].max())
        xs = np.geomspace(max(lo, 1e-9), hi, 200) if r["function"] == "weibull" and lo > 0 \
            else np.linspace(lo, hi, 200)
        crit = r["criterion"]
        for f in r["fits"]:
            if f["track"] != name:
                continue
            line, = ax.plot(xs, _curve(f, r, xs), lw=0.8, alpha=0.8)
            if f["threshold"] is not None:
                lo_, hi_ = f["ci_low"], f["ci_high"]
                if lo_ is not None and hi_ is not None:
                    ax.plot([lo_, hi_], [crit, crit], color=line.get_color(), lw=2.0,
                            alpha=0.35, solid_capstyle="butt")
                ax.plot([f["threshold"]], [crit], marker="|", ms=9, mew=1.5,
                        color=line.get_color(), ls="none")
        ax.axhline(crit, color="0.6", lw=0.6)
        mean = next(gr["threshold_mean"] for gr in r["group"] if gr["track"] == name)
        if mean is not None:
            ax.axvline(mean, color="k", ls="--", lw=0.8)
        if r["function"] == "weibull" and lo > 0:
            from matplotlib.ticker import NullFormatter, ScalarFormatter

            ax.set_xscale("log")  # plain numbers at the decades, no crowded minor labels
            ax.xaxis.set_major_formatter(ScalarFormatter())
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_ylim(0.35, 1.03)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel(f"intensity ({r['units']})")
        ax.set_ylabel("proportion correct")
    fig.suptitle(f"{a['id']}: {r['parameter']}, criterion {100 * r['criterion']:g} %",
                 fontsize=10)
    fig.tight_layout()
    return _save(fig, out, figure_prefix(a) + "psychometric")


def _curve(fit: dict, r: dict, xs: np.ndarray) -> np.ndarray:
    """A participant's fitted function at ``xs``, from its report entry (m and width are
    kept there on F's axis)."""
    from .psychometric import psi

    return psi(r["function"], xs, fit["m"], fit["width"], 0.5, fit["lapse"])
