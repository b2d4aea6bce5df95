"""Proportions against chance: identification scores (percent correct, over answers and with
each participant as the unit) and paired comparisons (which of two was chosen, per pair,
and the bias towards the first or the second felt)."""

from __future__ import annotations

import math

import pandas as pd
from scipy import special, stats

from ._base import StatsError, _check_columns, _tol
from .multicomp import p_adjust

__all__ = ["identification_scores", "participant_identification_test", "pair_preferences",
           "order_bias"]


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


# --------------------------------------------------------------------- paired comparisons
def _pairs_of(data: pd.DataFrame, first: str, second: str, chosen: str) -> pd.DataFrame:
    _check_columns(data, [first, second, chosen])
    d = data[[first, second, chosen]].astype(str)
    if d.empty:
        raise StatsError("no choices to analyse")
    bad = d[(d[chosen] != d[first]) & (d[chosen] != d[second])]
    if len(bad):
        r = bad.iloc[0]
        raise StatsError(f"{len(bad)} choice(s) name neither sample of their pair, first: "
                         f"{r[chosen]!r} of {r[first]!r} and {r[second]!r}")
    same = d[d[first] == d[second]]
    if len(same):
        raise StatsError(f"a pair of {same.iloc[0][first]!r} with itself")
    return d


def pair_preferences(data: pd.DataFrame, first: str, second: str, chosen: str,
                     levels: list[str] | None = None, padjust: str = "holm") -> pd.DataFrame:
    """Which sample of each pair was chosen (two-alternative forced choice), both orders of
    presentation pooled, with a two-sided exact binomial test of each pair against 1/2.

    Parameters
    ----------
    data : DataFrame, one row per choice
    first, second : str
        Columns naming the sample felt first and the one felt second.
    chosen : str
        Column naming the sample chosen (one of the two).
    levels : list of str, optional
        The samples' order: each pair is written with the earlier one as ``A``. Default:
        their order of first appearance.
    padjust : str
        Correction over the pairs (:func:`p_adjust`): ``holm`` (default), ``bonf``,
        ``fdr_bh`` or ``none``.

    Returns
    -------
    DataFrame, one row per pair presented
        ``A``, ``B``, ``n`` (choices between them), ``chose_A``, ``prop_A`` (the share that
        chose ``A``), ``A_first`` (choices made with ``A`` felt first), ``p_unc`` (exact
        binomial, two-sided, as R's ``binom.test(chose_A, n, 0.5)``) and ``p_corr``.

    Notes
    -----
    Each choice counts as independent: a person's repeated choices of one pair are not
    told apart (with one choice per order and person, as the comparison protocol has, a
    pair's n is twice the number of people).

    Examples
    --------
    >>> import pandas as pd
    >>> d = pd.DataFrame({"first": ["a", "b", "a", "b", "a", "b"],
    ...                   "second": ["b", "a", "b", "a", "b", "a"],
    ...                   "chosen": ["a", "a", "a", "a", "a", "b"]})
    >>> pair_preferences(d, "first", "second", "chosen")[["A", "B", "n", "chose_A", "p_unc"]]
       A  B  n  chose_A    p_unc
    0  a  b  6        5  0.21875
    """
    d = _pairs_of(data, first, second, chosen)
    seen = list(dict.fromkeys([*d[first], *d[second]]))
    order = list(levels) if levels is not None else seen
    missing = [s for s in seen if s not in order]
    if missing:
        raise StatsError(f"samples {missing} are not among the levels {order}")
    rank = {s: i for i, s in enumerate(order)}
    rows = []
    a_of = [min(f, s, key=rank.__getitem__) for f, s in zip(d[first], d[second], strict=True)]
    b_of = [max(f, s, key=rank.__getitem__) for f, s in zip(d[first], d[second], strict=True)]
    d = d.assign(_A=a_of, _B=b_of)
    for (a, b), g in d.groupby(["_A", "_B"], sort=False):
        n, k = len(g), int((g[chosen] == a).sum())
        rows.append({"A": a, "B": b, "n": n, "chose_A": k, "prop_A": k / n,
                     "A_first": int((g[first] == a).sum()),
                     "p_unc": float(stats.binomtest(k, n, 0.5).pvalue)})
    out = pd.DataFrame(rows)
    out = out.sort_values(["A", "B"], key=lambda c: c.map(rank), ignore_index=True)
    out["p_corr"] = p_adjust(out["p_unc"].to_numpy(), padjust)
    out.attrs["padjust"] = padjust
    return out


def order_bias(data: pd.DataFrame, first: str, second: str, chosen: str) -> pd.DataFrame:
    """How often the sample felt first was chosen, against 1/2 (two-sided exact binomial, as
    R's ``binom.test``): a bias of the procedure, not of the samples, which a design with
    both orders of every pair cancels in each pair's proportion.

    Returns
    -------
    DataFrame, one row
        ``n``, ``chose_first``, ``prop_first``, ``p_unc``.

    Examples
    --------
    >>> import pandas as pd
    >>> d = pd.DataFrame({"f": ["a", "b", "a", "b"], "s": ["b", "a", "b", "a"],
    ...                   "c": ["a", "b", "a", "a"]})
    >>> order_bias(d, "f", "s", "c")
       n  chose_first  prop_first  p_unc
    0  4            3        0.75  0.625
    """
    d = _pairs_of(data, first, second, chosen)
    n, k = len(d), int((d[chosen] == d[first]).sum())
    return pd.DataFrame([{"n": n, "chose_first": k, "prop_first": k / n,
                          "p_unc": float(stats.binomtest(k, n, 0.5).pvalue)}])
