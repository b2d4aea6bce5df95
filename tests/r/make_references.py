"""Recompute tests/r/references.csv with R (Debian's r-base-core and r-cran-* packages).

    .venv/bin/python tests/r/make_references.py [OUT.csv]

Writes each study of ``studies.py`` to CSV in a temporary folder, runs ``reference.R`` on
it and gathers the rows (study, analysis, term, stat, value, call).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import studies  # noqa: E402

KINDS = {"factorial": "factorial", "crossed_2x3": "crossed"}


def compute(out: Path) -> pd.DataFrame:
    """Run R on every study; the references as one table (also written to ``out``)."""
    rscript = shutil.which("Rscript")
    if rscript is None:
        raise RuntimeError("Rscript not found: `make test` installs r-base-core")
    parts = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, make in studies.STUDIES.items():
            src, dst = Path(tmp, f"{name}.csv"), Path(tmp, f"ref_{name}.csv")
            make().to_csv(src, index=False)
            subprocess.run([rscript, str(HERE / "reference.R"), str(src), name,
                            KINDS.get(name, "oneway"), str(dst)], check=True,
                           capture_output=True, text=True, timeout=600)
            parts.append(pd.read_csv(dst))
    table = pd.concat(parts, ignore_index=True)
    table.to_csv(out, index=False, float_format="%.17g")
    return table


if __name__ == "__main__":
    compute(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "references.csv")
