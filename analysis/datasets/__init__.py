"""A small committed dataset for the docstrings' examples and for trying the API.

* ``ratings`` — one-way design: 6 simulated participants rated 6 samples twice on a 1–9
  scale (``tests/data/protocols/six_on_nine.toml``); columns ``participant``, ``sample``,
  ``repetition``, ``rating``.
* ``crossed`` — a 2 × 3 design (spring soft/firm × transient none/pulse/ring), 6 simulated
  participants, two repetitions, 1–7 (``two_by_three.toml``); columns ``participant``,
  ``sample``, ``spring``, ``transient``, ``repetition``, ``rating``.
* :func:`sessions_path` — three of the ``ratings`` participants' session folders as
  recorded (session.json, protocol.toml, trials.tsv), for :func:`analysis.load_sessions`.

The participants are simulated (a rehearsal model, not people); a saturated attempt that
reached the protocol's cap leaves a cell with one repetition.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import pandas as pd

__all__ = ["read_dataset", "sessions_path", "DATASETS"]

DATASETS = ("ratings", "crossed")


def read_dataset(name: str) -> pd.DataFrame:
    """One of :data:`DATASETS` as a long-format DataFrame.

    Examples
    --------
    >>> from analysis.datasets import read_dataset
    >>> df = read_dataset("ratings")
    >>> df.shape, sorted(df["sample"].unique())
    ((71, 4), ['firm', 'foam', 'pulse', 'ring', 'soft', 'wood'])
    """
    if name not in DATASETS:
        raise ValueError(f"no dataset {name!r}; available: {', '.join(DATASETS)}")
    with resources.files("analysis.datasets").joinpath(f"{name}.csv").open() as f:
        return pd.read_csv(f)


def sessions_path() -> Path:
    """The folder of the example session folders (``sub-P01/ses-1``, …)."""
    return Path(str(resources.files("analysis.datasets").joinpath("sessions")))
