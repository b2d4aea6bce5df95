"""How the report writes numbers and tables: shared by the report's page
(:mod:`analysis.report`) and each analysis type's sections (:mod:`analysis.analyses`).

APA style throughout: p without a leading zero, ``p < .001`` below that, and as many digits
as it takes to show which side of .05 a p lies; user-given text escaped, so no raw HTML
reaches the page.
"""

from __future__ import annotations

import html
import math

import pandas as pd

__all__ = ["people", "table", "p_digits", "p_text", "md_text", "scale_text", "anova_rows",
           "nan_to_none"]


def people(n) -> str:
    """'1 participant', '9 participants'."""
    return f"{n} participant{'' if n == 1 else 's'}"


def left_out_text(res, what: str) -> str:
    """The methods' sentence on the participants of the selected sessions an analysis whose
    every participant with a valid ``what`` is in it left out (``res["exclusions"]``,
    ``res["n_selected"]``: :func:`analysis.study.not_analysed`), or "" when none was."""
    n = sum(int(r["n_excluded"]) for r in res["exclusions"])
    if not n:
        return ""
    return (f" Of the {people(res['n_selected'])} of the selected sessions, {n} gave no "
            f"valid {what} in this phase (never reached it, or every attempt excluded) and "
            f"{'is' if n == 1 else 'are'} listed under exclusions.")


def scale_text(design: dict) -> str:
    """The rating scale of a recorded design, '1–7', or '—' without one."""
    s = design.get("scale")
    return f"{s['min']}–{s['max']}" if s else "—"


def md_text(text: str) -> str:
    """User-given text (titles, names) in Markdown prose: no raw HTML gets through."""
    return html.escape(str(text), quote=False)


def p_digits(p: float, alpha: float = 0.05) -> str:
    """p without ``p =`` and leading zero: 3 decimals below .1, else 2, and more when
    rounding would carry it across ``alpha`` (.0496 is ".0496", never ".050")."""
    digits = 3 if p < 0.1 else 2
    while digits < 15 and (p < alpha) != (round(p, digits) < alpha):
        digits += 1
    return f"{p:.{digits}f}".lstrip("0")


def p_text(p: float) -> str:
    """APA style: ``p < .001``, else ``p = `` with 2–3 decimals and no leading zero, with as
    many more as it takes to show which side of .05 it lies."""
    if p < 0.001:
        return "p < .001"
    return "p = " + p_digits(p)


#: a table cell listing participants names this many, then says how many more
NAMES_SHOWN = 20


def table(rows: list[dict], cols: list[str] | None = None) -> str:
    """A Markdown table of ``rows`` (every row's columns, or ``cols``); '*none*' when empty.
    p columns in APA style; every cell escaped, so no cell can add columns or raw HTML."""
    if not rows:
        return "*none*\n"
    cols = cols or list(dict.fromkeys(k for r in rows for k in r))  # every row's columns

    def fmt(v, col):
        if v is None:
            return "—"
        if col == "subjects_excluded" and isinstance(v, str) and v.count(",") >= NAMES_SHOWN:
            names = v.split(",")  # a long list of people: the first, and how many
            return (f"{', '.join(names[:NAMES_SHOWN])} and {len(names) - NAMES_SHOWN:,} more "
                    "(all in report.json)")
        if isinstance(v, float):
            if col.startswith("p_") or col in ("p", "p_spher"):
                return p_digits(v) if v >= 0.001 else "< .001"  # APA: no leading zero
            if v == 0:
                return "0"
            return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
        return str(v)

    def fmt_cell(v, col):
        return (html.escape(fmt(v, col), quote=False).replace("|", "\\|")
                .replace("\n", " ").replace("\r", " "))

    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(fmt_cell(r.get(c, ""), c) for c in cols) + " |" for r in rows]
    return "\n".join(lines) + "\n"


#: ANOVA columns that exist only for effects with more than one degree of freedom
_SPHERICITY = ("eps_gg", "eps_hf", "p_gg", "p_hf", "W_mauchly", "p_spher")


def anova_rows(aov: pd.DataFrame) -> list[dict]:
    """The ANOVA table as rows; a sphericity column is left out of a row where it does not
    apply (a one-df effect), instead of a NaN. Any other NaN still stops the report."""
    rows = []
    for r in aov.to_dict(orient="records"):
        rows.append({k: v for k, v in r.items()
                     if not (k in _SPHERICITY and isinstance(v, float) and math.isnan(v))})
    return rows


def nan_to_none(rows: list[dict]) -> list[dict]:
    """Rows with each NaN made None (null in JSON, '—' in a table): a value that does not
    exist, said so."""
    return [{k: (None if isinstance(x, float) and math.isnan(x) else x) for k, x in r.items()}
            for r in rows]
