"""``hapticlab bench orderings``: does the simulated study reproduce the papers' orderings?

For each study seed (``--seeds``, default 1–5) the demo's study is simulated (realism 9,
factorial 9, identification 6 experts + 8 novices; :data:`app.demo.STUDY`) into a
temporary folder and analysed as ``hapticlab analyze`` would. Per seed:

* realism — the samples by mean rating; the mean rank of the paper's four classes (wood;
  wood_on_foam and the matched samples; pulse and sinusoid; foam and the springs; Kuchenbecker
  et al., Fig. 6 and text) and whether the classes come in the paper's order; saturations
  per participant in testing (paper: mean 5, range 0–11); participants the repeated-measures
  ANOVA dropped listwise because the saturation cap left a cell empty; the paper's "not
  distinguishable" pairs tested for equivalence (TOST within one rating point) beside the
  paper's paired t-test;
* factorial — each material's best set and most significant factor against Table 2 and the
  text of the reality-based models (best: rubber LLL at −240 1/s, 60 1/s, 30 Hz; wood
  −150, 80, 100 Hz; aluminum −300, 90, 300 Hz; most significant: decay for rubber,
  frequency for wood, slope for aluminum);
* identification — percent of repetitions with all three named right, by group and on the
  third repetition (Table 3: 83.3 % overall, 88.9 % experts, 79.2 % novices, 85.7 % third),
  and the most common confusion (paper: wood–rubber).

The baseline is the paper: each row prints the paper's value beside the simulated ones and
the summary gives the median and range over seeds.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from collections import Counter
from pathlib import Path

from ._common import emit, parse_seeds, print_table

CLASSES = {"wood": ("wood",), "wood_on_foam+matched": ("wood_on_foam", "matched_firm",
                                                        "matched_soft"),
           "pulse+sinusoid": ("pulse_firm", "pulse_soft", "sinusoid_firm", "sinusoid_soft"),
           "foam+springs": ("foam", "firm_spring", "soft_spring")}
#: Table 2 of the reality-based models: the best set per material (slope, decay, frequency).
PAPER_BEST = {"rubber": {"slope": -240.0, "decay": 60.0, "frequency": 30.0},
              "wood": {"slope": -150.0, "decay": 80.0, "frequency": 100.0},
              "aluminum": {"slope": -300.0, "decay": 90.0, "frequency": 300.0}}
PAPER_MOST = {"rubber": "decay", "wood": "frequency", "aluminum": "slope"}
#: the pairs the realism paper found not distinguishable (paired t-tests on per-user means)
PAPER_ALIKE = (("matched_firm", "wood_on_foam"), ("matched_soft", "wood_on_foam"),
               ("matched_firm", "matched_soft"), ("firm_spring", "foam"))
#: the margin they are tested equivalent within [rating points of the 1–7 scale]: one step
#: of the scale, the smallest difference a single rating can state
ALIKE_BOUND = 1.0
PAPER_ID = {"all": 83.3, "group expert": 88.9, "group novice": 79.2, "repetition 1": None,
            "repetition 3": 85.7}



def _realism(data, protocol: str = "realism") -> dict:
    from analysis.analyses import analyse_recorded

    res = analyse_recorded(data, protocol, "testing")
    r = res["result"]
    means = {s["sample"]: s["mean"] for s in r["samples"]}
    order = sorted(means, key=means.get, reverse=True)
    rank = {s: i + 1 for i, s in enumerate(order)}
    cls = {c: statistics.mean(rank[s] for s in members if s in rank)
           for c, members in CLASSES.items()}
    names = list(CLASSES)
    in_order = all(cls[a] < cls[b] for a, b in zip(names, names[1:], strict=False))
    rows = data[(data["protocol"] == protocol) & (data["phase"] == "testing")]
    sat = rows[rows["status"].isin(["saturated", "excluded_saturated"])]
    per = sat.groupby("participant").size().reindex(rows["participant"].unique(), fill_value=0)
    n_all = int(rows["participant"].nunique())
    n_anova = int(r["anova"]["n"].iloc[0]) if "n" in r["anova"] else \
        int(r.get("n_subjects", n_all))
    return {"order": order, "class_rank": cls, "classes_in_order": in_order,
            "wood_first": order[0] == "wood", "wood_on_foam_rank": rank.get("wood_on_foam"),
            "saturations_mean": float(per.mean()), "saturations_min": int(per.min()),
            "saturations_max": int(per.max()), "participants": n_all,
            "anova_n": n_anova, "dropped_listwise": n_all - n_anova}


def _alike(data, protocol: str = "realism") -> list[dict]:
    """The paper's "not distinguishable" pairs, tested for equivalence within
    :data:`ALIKE_BOUND` (two one-sided tests, 90 % CI) beside the paper's paired t-test: a
    non-significant t-test with 9 participants is what a real difference gives too."""
    from analysis import equivalence_ttests, pairwise_ttests

    rows = data[(data["protocol"] == protocol) & (data["phase"] == "testing")
                & data["valid"] & data["rating"].notna()]
    args = (rows, "rating", "sample", "participant")
    rated = set(rows["sample"])
    pairs = [(a, b) for a, b in PAPER_ALIKE if {a, b} <= rated]
    eq = equivalence_ttests(*args, ALIKE_BOUND, pairs=pairs)
    pw = pairwise_ttests(*args, padjust="none")
    p_t = {frozenset((r.A, r.B)): r.p_unc for r in pw.itertuples()}
    out = []
    for a, b in PAPER_ALIKE:
        r = eq[(eq["A"] == a) & (eq["B"] == b)]
        if r.empty:
            why = next((w for x, y, w in eq.attrs["constant_pairs"] if {x, y} == {a, b}),
                       f"{a if a not in rated else b} has no valid rating")
            out.append({"pair": f"{a}–{b}", "verdict": f"no test: {why}"})
            continue
        r = r.iloc[0]
        out.append({"pair": f"{a}–{b}", "mean_diff": float(r.mean_diff),
                    "ci90": [float(r.ci_low), float(r.ci_high)], "p_tost": float(r.p),
                    "equivalent": bool(r.equivalent), "bound_reached": float(r.bound_reached),
                    "p_ttest": float(p_t[frozenset((a, b))]),
                    "verdict": (f"equivalent within ±{ALIKE_BOUND:g}" if r.equivalent else
                                f"not shown alike (±{r.bound_reached:.2f} reached)")})
    return out


def _factorial(data, protocol) -> dict:
    from analysis.analyses import analyse_recorded

    res = analyse_recorded(data, "factorial", "rating")["result"]
    out = {}
    for mat, paper in PAPER_BEST.items():
        r = res[mat]
        best = r["best_set"]
        # the levels of the paper's best set in this protocol's low/high coding
        levels = next((dict(sm.factors) for sm in protocol.samples.values()
                       if sm.block == mat and sm.factors
                       and all(abs(sm.params[f] - v) <= 1e-6 * abs(v) for f, v in paper.items())),
                      {})
        best_levels = {f: best.get(f) for f in paper}
        out[mat] = {"best_sample": best["sample"], "best_levels": best_levels,
                    "paper_levels": levels,
                    "best_matches_paper": bool(levels) and all(
                        best_levels[f] == levels[f] for f in paper),
                    "levels_matching_paper": sum(best_levels[f] == levels.get(f) for f in paper),
                    "most_significant": r["most_significant"],
                    "most_significant_p": r["most_significant_p"],
                    "most_matches_paper": r["most_significant"] == PAPER_MOST[mat]}
    return out


def _identification(data) -> dict:
    from analysis.analyses import analyse_recorded

    res = analyse_recorded(data, "identification", "identification")["result"]
    t = {row["scope"]: row["percent"] for row in res["table"].to_dict(orient="records")}
    conf = res.get("confusion")
    pairs = Counter()
    if conf is not None:
        c = conf if hasattr(conf, "index") else None
        if c is not None:
            for truth in c.index:
                for answer in c.columns:
                    if truth != answer and str(truth) in PAPER_BEST and str(answer) in PAPER_BEST:
                        pairs["–".join(sorted((str(truth), str(answer))))] += int(c.loc[truth,
                                                                                   answer])
    top = pairs.most_common(1)[0] if pairs and pairs.most_common(1)[0][1] > 0 else (None, 0)
    return {"percent": t, "top_confusion": top[0], "top_confusion_count": top[1],
            "confusions": dict(pairs)}


def _uncapped_realism(root: Path) -> Path:
    """realism.toml with the paper's redraw without a cap (``max_attempts = "none"``)."""
    from protocols import load_protocol

    text = load_protocol("realism").text
    line = next(ln for ln in text.splitlines() if ln.startswith("max_attempts"))
    path = root / "realism_uncapped.toml"
    path.write_text(text.replace(line, 'max_attempts = "none"', 1)
                    .replace('name = "realism"', 'name = "realism_uncapped"', 1))
    return path


def run_seed(seed: int, root: Path) -> dict:
    """Simulate and analyse one study seed into ``root``: the demo's study, and realism
    again without the saturation cap (same participants: same seed)."""
    from analysis import load_sessions
    from app.api import simulate_study as simulate
    from app.demo import simulate_demo_study
    from protocols import load_protocol

    data = root / f"seed-{seed}"
    t0 = time.perf_counter()
    simulate_demo_study(data, seed)
    d = load_sessions(data)
    out = {"seed": seed, "realism": _realism(d), "alike": _alike(d),
           "factorial": _factorial(d, load_protocol("factorial")),
           "identification": _identification(d)}
    free = root / f"seed-{seed}-uncapped"
    simulate(_uncapped_realism(root), 9, seed=seed * 10, data=free, prefix="R",
             traces="contacts")  # the demo's realism seed (app.demo.simulate_demo_study)
    out["realism_uncapped"] = _realism(load_sessions(free), "realism_uncapped")
    out["seconds"] = time.perf_counter() - t0
    return out


def _spread(values) -> str:
    v = [x for x in values if x is not None]
    if not v:
        return "—"
    return f"{statistics.median(v):.3g} [{min(v):.3g}, {max(v):.3g}]"


def main(args) -> int:
    seeds = parse_seeds(getattr(args, "seeds", None), [1, 2, 3, 4, 5])
    own_store = "HAPTICLAB_LIBRARIES" not in os.environ
    with tempfile.TemporaryDirectory(prefix="hapticlab-orderings-") as tmp:
        if own_store:
            os.environ["HAPTICLAB_LIBRARIES"] = str(Path(tmp) / "libraries")
        try:
            runs = [run_seed(s, Path(tmp)) for s in seeds]
        finally:
            if own_store:
                os.environ.pop("HAPTICLAB_LIBRARIES", None)
    if args.json:
        emit({"seeds": seeds, "runs": runs}, True)
        return 0
    print_table("realism: mean rank of the paper's classes (1 = most realistic) per seed",
                ["seed", *CLASSES, "paper order", "wood 1st", "wood_on_foam rank",
                 "saturations/participant", "ANOVA n of"],
                [(r["seed"], *(f"{r['realism']['class_rank'][c]:.1f}" for c in CLASSES),
                  r["realism"]["classes_in_order"], r["realism"]["wood_first"],
                  r["realism"]["wood_on_foam_rank"],
                  f"{r['realism']['saturations_mean']:.1f} ({r['realism']['saturations_min']}–"
                  f"{r['realism']['saturations_max']})",
                  f"{r['realism']['anova_n']} of {r['realism']['participants']}") for r in runs])
    print_table("realism: what the saturation cap of 3 costs (same participants, same seed)",
                ["seed", "cap 3: ANOVA n", "saturations/participant", "no cap: ANOVA n",
                 "saturations/participant", "classes in paper order (no cap)"],
                [(r["seed"], f"{r['realism']['anova_n']} of {r['realism']['participants']}",
                  f"{r['realism']['saturations_mean']:.1f}",
                  f"{r['realism_uncapped']['anova_n']} of "
                  f"{r['realism_uncapped']['participants']}",
                  f"{r['realism_uncapped']['saturations_mean']:.1f} "
                  f"({r['realism_uncapped']['saturations_min']}–"
                  f"{r['realism_uncapped']['saturations_max']})",
                  r["realism_uncapped"]["classes_in_order"]) for r in runs])
    print_table(f"realism: the paper's \"not distinguishable\" pairs, tested equivalent within "
                f"±{ALIKE_BOUND:g} rating point (TOST at .05; paired t-test p beside)",
                ["pair", "seed", "A − B [90 % CI]", "TOST p", "verdict", "t-test p"],
                [(a["pair"], r["seed"],
                  f"{a['mean_diff']:+.2f} [{a['ci90'][0]:+.2f}, {a['ci90'][1]:+.2f}]"
                  if "mean_diff" in a else "—",
                  f"{a['p_tost']:.3f}" if "p_tost" in a else "—", a["verdict"],
                  f"{a['p_ttest']:.3f}" if "p_ttest" in a else "—")
                 for i in range(len(PAPER_ALIKE)) for r in runs for a in (r["alike"][i],)])
    rows = []
    for mat in PAPER_BEST:
        for r in runs:
            f = r["factorial"][mat]
            rows.append((mat, r["seed"], f["best_sample"], f"{f['levels_matching_paper']}/3",
                         f"{f['most_significant']} (p = {f['most_significant_p']:.3f})",
                         PAPER_MOST[mat]))
    print_table("factorial: best set and most significant factor (paper: Table 2 and text)",
                ["material", "seed", "best set", "levels as paper's best", "most significant",
                 "paper"], rows)
    scopes = list(PAPER_ID)
    print_table("identification: % of repetitions all named right",
                ["scope", "paper", "simulated median [min, max]"],
                [(s, "—" if PAPER_ID[s] is None else PAPER_ID[s],
                  _spread([r["identification"]["percent"].get(s) for r in runs]))
                 for s in scopes]
                + [("top confusion", "wood–rubber", ", ".join(
                    f"{i['top_confusion']} ({i['top_confusion_count']})"
                    for i in (r["identification"] for r in runs)))])
    print(f"{len(seeds)} seeds; {statistics.median(r['seconds'] for r in runs):.0f} s per seed "
          "(median)")
    return 0
