"""Identification scores: percent correct against chance, over answers and with each
participant as the unit."""

from __future__ import annotations

import math

import pandas as pd
from scipy import special, stats

from ._base import StatsError, _check_columns, _tol

__all__ = ["identification_scores", "participant_identification_test"]


# --------------------------------------------------------------------- identification
def identification_scores(data: pd.DataFrame, subject: str, correct: str,
                          repetition: str | None = None, group: str | None = None,
                          chance: float = 1 / 6, answer: str | None = None,
                          truth: str | None = None) -> dict[str, pd.DataFrame]:
    """Percent correct overall, per repetition and per group, with binomial tests against chance.

    Parameters
    ----------
    correct : column of 0/1 (1: all surfaces named right)
    chance : float
        Probability of a correct answer by guessing: naming three surfaces at random is
        right in 1 of 3! = 6 orders.
    answer, truth : columns of comma-separated names (as answered, as presented), for the
        confusion matrix.

    Returns
    -------
    dict of DataFrames
        ``summary``: ``scope`` (all, repetition k, last repetition, group g), ``n``,
        ``correct``, ``incorrect``, ``percent``, ``chance_percent``, ``p_binom``
        (one-sided exact binomial test, P(X ≥ correct) by chance);
        ``confusion`` (when answer and truth are given): rows presented, columns answered,
        counts per surface.

    Notes
    -----
    p_binom = Σ_{k' ≥ k} C(n, k') · chance^k' · (1 − chance)^(n − k').

    Examples
    --------
    The published counts (Table 3 of the reality-based models: 35 of 42 answers right):

    >>> import pandas as pd
    >>> from analysis import identification_scores
    >>> d = pd.DataFrame({"participant": [f"S{i // 3}" for i in range(42)],
    ...                   "correct": [1] * 35 + [0] * 7})
    >>> identification_scores(d, "participant", "correct")["summary"][
    ...     ["scope", "n", "correct", "percent"]].round(1)
      scope   n  correct  percent
    0   all  42       35     83.3
    """
    cols = [subject, correct] + [c for c in (repetition, group, answer, truth) if c]
    _check_columns(data, cols)
    c = pd.to_numeric(data[correct], errors="coerce")
    if c.isna().any() or not c.isin([0, 1]).all():
        raise StatsError(f"column {correct!r} must hold 0 or 1 for every answer")
    rows = []

    def add(scope, mask):
        k = int(c[mask].sum())
        n = int(mask.sum())
        if n == 0:
            return
        rows.append({"scope": scope, "n": n, "correct": k, "incorrect": n - k,
                     "percent": 100.0 * k / n, "chance_percent": 100.0 * chance,
                     "p_binom": float(stats.binomtest(k, n, chance,
                                                      alternative="greater").pvalue)})

    all_rows = pd.Series(True, index=data.index)
    add("all", all_rows)
    if repetition:
        reps = pd.to_numeric(data[repetition], errors="coerce")
        for r in sorted(reps.dropna().unique()):
            add(f"repetition {int(r)}", reps == r)
        last = reps == reps.groupby(data[subject]).transform("max")
        add("last repetition", last)
    if group:
        for g in sorted(data[group].dropna().astype(str).unique()):
            if g:
                add(f"group {g}", data[group].astype(str) == g)
    out = {"summary": pd.DataFrame(rows)}
    if answer and truth:
        pairs = []
        for a, t in zip(data[answer].astype(str), data[truth].astype(str), strict=True):
            pairs += list(zip(t.split(","), a.split(","), strict=False))
        names = sorted({p for pair in pairs for p in pair if p})
        conf = pd.DataFrame(0, index=pd.Index(names, name="presented"),
                            columns=pd.Index(names, name="answered"))
        for t, a in pairs:
            if t and a:
                conf.loc[t, a] += 1
        out["confusion"] = conf
    return out


def participant_identification_test(data: pd.DataFrame, subject: str, correct: str,
                                    chance: float = 1 / 6, group: str | None = None
                                    ) -> pd.DataFrame:
    """Identification against chance with each person as the unit (repeated answers).

    Each participant's proportion of correct repetitions is one observation; a one-sided
    exact sign test asks whether more participants than chance would give are above the
    chance proportion, and a one-sample t-test compares the mean proportion with chance.
    Unlike the binomial test over all answers, neither treats one person's repeated answers
    as independent.

    With ``group`` (a between-subject factor, e.g. expert/novice) and exactly two groups,
    the groups' proportions are compared by a two-sided Mann–Whitney U test (exact for
    small groups without ties; scipy's ``method="auto"``): ``attrs["groups"]`` holds
    ``group_a``, ``group_b``, ``n_a``, ``n_b``, ``mean_percent_a``, ``mean_percent_b``,
    ``U``, ``p_mwu``.

    Returns
    -------
    DataFrame, one row
        ``n`` (participants), ``mean_percent``, ``chance_percent``, ``above`` (participants
        above chance), ``p_sign`` (one-sided exact sign test of ``above`` against 1/2 among
        participants not at chance), ``t``, ``dof``, ``p_t`` (one-sided).
    """
    _check_columns(data, [subject, correct])
    c = pd.to_numeric(data[correct], errors="coerce")
    if c.isna().any() or not c.isin([0, 1]).all():
        raise StatsError(f"column {correct!r} must hold 0 or 1 for every answer")
    p = c.groupby(data[subject], observed=True).mean()
    n = int(p.size)
    if n < 2:
        raise StatsError(f"a per-participant test needs at least 2 participants, has {n}")
    above, below = int((p > chance).sum()), int((p < chance).sum())
    p_sign = float(stats.binomtest(above, above + below, 0.5, alternative="greater").pvalue) \
        if above + below else 1.0
    sd = float(p.std(ddof=1))
    row = {"n": n, "mean_percent": 100 * float(p.mean()), "chance_percent": 100 * chance,
           "above": above, "p_sign": p_sign}
    if sd > _tol(p.to_numpy()) + 1e-15:
        t = (float(p.mean()) - chance) / (sd / math.sqrt(n))
        row.update(t=t, dof=n - 1, p_t=float(special.stdtr(n - 1, -t)))
    out = pd.DataFrame([row])
    if group is not None:
        _check_columns(data, [group])
        g = data.groupby(subject, observed=True)[group].first().astype(str)
        names = sorted(x for x in g.unique() if x)
        if len(names) == 2:
            a, b = (p[g.reindex(p.index) == x] for x in names)
            if len(a) and len(b):
                res = stats.mannwhitneyu(a, b, alternative="two-sided", method="auto")
                out.attrs["groups"] = {"group_a": names[0], "group_b": names[1],
                                       "n_a": int(len(a)), "n_b": int(len(b)),
                                       "mean_percent_a": 100 * float(a.mean()),
                                       "mean_percent_b": 100 * float(b.mean()),
                                       "U": float(res.statistic), "p_mwu": float(res.pvalue)}
    return out
