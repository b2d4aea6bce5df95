"""The report from real (simulated, headless) session folders."""

import json
import subprocess
import sys

import pytest

from analysis import load_sessions
from analysis.report import analyze

pytestmark = [pytest.mark.integration]

CLI = [sys.executable, "-m", "app"]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    data = tmp_path_factory.mktemp("study")
    common = ["--dry-run", "--no-audio", "--quiet"]
    for i in range(3):
        for proto, pid, extra in (("realism", f"R{i}", ["--traces", "contacts"]),
                                  ("factorial", f"F{i}", ["--traces", "none"]),
                                  ("identification", f"I{i}", ["--traces", "none", "--group",
                                                               "expert" if i else "novice"])):
            out = subprocess.run([*CLI, "run", proto, "--participant", pid, "--seed", str(i + 1),
                                  "--data", str(data), *common, *extra],
                                 capture_output=True, text=True, timeout=600)
            assert out.returncode == 0, out.stderr
    return data


def _no_nan(obj):
    json.loads(json.dumps(obj), parse_constant=lambda c: pytest.fail(f"{c} in the report"))


@pytest.mark.slow
def test_load_sessions(study):
    d = load_sessions(study)
    assert d.attrs["sessions"] == 9 and d["participant"].nunique() == 9
    assert set(d["protocol"]) == {"realism", "factorial", "identification"}
    fac = d[d["protocol"] == "factorial"]
    rated = fac[fac["status"] != "reference"]
    assert set(rated["frequency"]) == {"low", "high"} and set(rated["block"]) == {
        "rubber", "wood", "aluminum"}
    refs = fac[fac["status"] == "reference"]  # the real blocks, one per material block
    assert set(refs["frequency"]) == {""} and len(refs) == 3 * 3
    assert set(refs["sample"]) == {"rubber-real", "wood-real", "aluminum-real"}
    assert d.attrs["files"] and not d.attrs["torn"]
    t = d.attrs["session_table"]
    assert set(t["kind"]) == {"dry-run"} and set(t["status"]) == {"complete"}
    assert len(d.attrs["designs"]) == 3  # one design per protocol


def _analysis(rep, id_):
    return next(a for a in rep["analyses"] if a["id"] == id_)


@pytest.mark.slow
def test_report_structure_and_numbers(study, tmp_path):
    rep = analyze(study, tmp_path / "r")
    _no_nan(rep)
    assert [a["id"] for a in rep["analyses"]] == [
        "factorial/rating", "identification/identification", "realism/testing"]
    r = _analysis(rep, "realism/testing")
    assert r["type"] == "oneway" and r["design"]["within"] == ["sample"]
    assert {s["sample"] for s in r["samples"]} >= {"wood", "foam", "matched_firm"}
    assert len(r["samples"]) == 11
    assert len(r["pairwise"]) + len(r["constant_pairs"]) == 55
    assert set(r["samples"][0]) >= {"sample", "mean", "ci_low", "ci_high", "mean_z"}
    assert set(r["pairwise"][0]) >= {"A", "B", "t", "dof", "p_unc", "p_holm", "dz", "n"}
    assert r["anova"][0]["Source"] == "sample" and "eps_gg" in r["anova"][0]
    # 3 participants, 11 samples: Mauchly's test is undefined and said to be, not p = 0
    assert "p_spher" not in r["anova"][0] and "Mauchly" in r["anova_notes"][0]
    f = _analysis(rep, "factorial/rating")
    assert f["type"] == "factorial" and f["design"]["by"] == "block"
    for m in ("rubber", "wood", "aluminum"):
        g = f["groups"][m]
        assert g["most_significant"] in ("frequency", "decay", "slope")
        assert set(g["best_set"]) >= {"frequency", "decay", "slope", "sample"}
        assert len(g["anova"]) == 7 and all("DF_err" in row for row in g["anova"])
        assert [e["factor"] for e in g["main_effects"]] == ["frequency", "decay", "slope"]
    i = _analysis(rep, "identification/identification")
    t = {row["scope"]: row for row in i["table"]}
    assert t["all"]["n"] == 9 and "last repetition" in t and "group expert" in t
    dev = r["device"]
    assert dev["n_taps"] > 0 and 0.05 < dev["velocity_mean"] < 0.2
    assert rep["provenance"]["seeds"] == [1, 2, 3]
    # the methods are written from the data: the scale and the counts of this study
    assert "rated 11 samples on a 1–7 scale" in r["methods"] and "all 55 pairs" in r["methods"]
    assert "on a 1–10 scale" in f["methods"] and "2 × 2 × 2" in f["methods"]
    assert "chance 1/3! = 16.7 %" in i["methods"]
    assert rep["methods"].startswith("These data come from a dry run")
    out = tmp_path / "r"
    for name in ("report.json", "report.md", "report.html", "realism-testing_means.png",
                 "realism-testing_means.svg", "realism-testing_pvalues.png",
                 "factorial-rating_wood.png", "identification-identification_confusion.png",
                 "realism-testing_accel_traces.png"):
        assert (out / name).stat().st_size > 500, name
    assert "Greenhouse–Geisser" in (out / "report.md").read_text()
    assert "<table>" in (out / "report.html").read_text()


@pytest.mark.slow
def test_rerun_gives_identical_numbers(study, tmp_path):
    a = analyze(study, tmp_path / "a", ("json",))
    b = analyze(study, tmp_path / "b", ("json",))
    assert (tmp_path / "a" / "report.json").read_text() == (tmp_path / "b" /
                                                             "report.json").read_text()
    assert a == b


@pytest.mark.slow
def test_cli_analyze_and_its_errors(study, tmp_path):
    out = subprocess.run([*CLI, "analyze", str(study), "--out", str(tmp_path / "o"), "--format",
                          "json"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "o" / "report.json").exists()
    bad = subprocess.run([*CLI, "analyze", str(tmp_path / "none"), "--out", str(tmp_path / "x")],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "no such folder" in bad.stderr and "Traceback" not in bad.stderr
    fmt = subprocess.run([*CLI, "analyze", str(study), "--out", str(tmp_path / "y"), "--format",
                          "pdf"], capture_output=True, text=True)
    assert fmt.returncode == 2 and "--format" in fmt.stderr


@pytest.mark.slow
def test_export_files_agree_with_the_report_cell_by_cell(study, tmp_path):
    """`hapticlab export` in every format, opened with pandas: the wide realism file is the
    report's per-participant means cell by cell (report.json keeps 12 significant digits);
    the identification file's repetition columns average to the report's per-repetition
    percentages; the long file holds every analysed trial and the codebook names every
    column of every file."""
    import pandas as pd

    rep = analyze(study, tmp_path / "r")
    files = {}
    for fmt in ("long-csv", "wide-csv", "jasp", "r", "spss"):
        out = subprocess.run([*CLI, "export", str(study), "--out", str(tmp_path / fmt),
                              "--format", fmt], capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        files[fmt] = tmp_path / fmt
    realism = _analysis(rep, "realism/testing")
    wide = pd.read_csv(files["wide-csv"] / "wide_realism_testing.csv", keep_default_na=False,
                       na_values=[""])
    wide = wide.set_index("participant")
    for row in realism["per_subject"]:
        for sample, value in row.items():
            if sample == "participant":
                continue
            got = wide.loc[row["participant"], sample]
            assert (pd.isna(got) and value is None) or got == pytest.approx(value, rel=1e-10)
    jasp = pd.read_csv(files["jasp"] / "wide_realism_testing.csv")
    assert all(c.replace("_", "").isalnum() for c in jasp.columns)
    assert "group" not in jasp.columns  # nobody in realism has a group: no empty column
    from analysis.load import DEVICE_COLUMNS

    device = list(DEVICE_COLUMNS)  # text: what each participant tapped on
    assert (jasp.set_index("participant")[device].astype(str).to_numpy()
            == wide[device].astype(str).to_numpy()).all()
    assert set(jasp["device_backend"]) == {"sim"}
    assert jasp.drop(columns=["participant", *device]).to_numpy() == pytest.approx(
        wide.drop(columns=device).to_numpy(), rel=1e-12, nan_ok=True)
    ident = _analysis(rep, "identification/identification")
    pct = {r["scope"]: r["percent"] for r in ident["table"]}
    wid = pd.read_csv(files["wide-csv"] / "wide_identification_identification.csv")
    for k in (1, 2, 3):
        assert 100 * wid[f"rep{k}"].mean() == pytest.approx(pct[f"repetition {k}"], rel=1e-10)
    long = pd.read_csv(files["long-csv"] / "long.csv", keep_default_na=False, na_values=[""])
    real_rows = long[(long["protocol"] == "realism")]
    assert set(real_rows["phase"]) == {"testing"} and real_rows["rating"].notna().all()
    means = real_rows.groupby(["participant", "sample"])["rating"].mean()
    for row in realism["per_subject"]:
        for sample, value in row.items():
            if sample != "participant" and value is not None:
                assert means[(row["participant"], sample)] == pytest.approx(value, rel=1e-10)
    assert (files["r"] / "load.R").read_text().count("factor(") >= 2
    # the factorial ANOVA's dependent variable is exported: an RM ANOVA on long.csv's
    # rating_z, and on the wide file's _z columns, gives the report's F per block
    import analysis as A

    fac = _analysis(rep, "factorial/rating")
    rows = long[long["protocol"] == "factorial"]
    wz = pd.read_csv(files["wide-csv"] / "wide_factorial_rating.csv").set_index("participant")
    for block, g in rows.groupby("block"):
        ours = A.rm_anova(g, "rating_z", ["frequency", "decay", "slope"], "participant")
        ref = {r["Source"]: r["F"] for r in fac["groups"][block]["anova"]}
        for r in ours.itertuples():
            assert r.F == pytest.approx(ref[r.Source], rel=1e-9), (block, r.Source)
        cells = g.groupby(["participant", "sample"])["rating_z"].mean()
        for (pid, sample), v in cells.items():
            assert wz.loc[pid, f"{sample}_z"] == pytest.approx(v, rel=1e-9, abs=1e-12)
    assert {"frequency_hz", "decay_per_s", "slope_per_s"} <= set(rows.columns)
    assert rows["frequency_hz"].gt(0).all()
    r_text = (files["r"] / "load.R").read_text()
    assert "str(d)" not in r_text and "rating_z" in r_text  # quiet when sourced
    import pyreadstat

    sav, meta = pyreadstat.read_sav(str(files["spss"] / "wide_factorial_rating.sav"))
    assert sav.shape[0] == wz.shape[0] and meta.column_names_to_labels["participant"]
    lsav, lmeta = pyreadstat.read_sav(str(files["spss"] / "long.sav"))
    assert len(lsav) == len(long) and lmeta.variable_value_labels["frequency"] == {
        1.0: "low", 2.0: "high"}
    for fmt, folder in files.items():
        book = pd.read_csv(folder / "codebook.csv", keep_default_na=False)
        for f in [*folder.glob("*.csv"), *folder.glob("*.sav")]:
            if f.name != "codebook.csv":
                cols = (set(pyreadstat.read_sav(str(f), metadataonly=True)[1].column_names)
                        if f.suffix == ".sav" else set(pd.read_csv(f, nrows=0).columns))
                assert cols <= set(book[book["file"] == f.name]["column"]), (fmt, f.name)
    assert "human" in set(book.loc[book["column"] == "kind", "meaning"].iloc[0].split())


@pytest.mark.r
@pytest.mark.slow
@pytest.mark.skipif(__import__("shutil").which("Rscript") is None,
                    reason="R missing: `make test` installs r-base-core and r-cran-*")
def test_r_reproduces_the_report_from_its_own_export(study, tmp_path):
    """The analyst's path: `hapticlab export --format r`, then load.R in R, then afex and
    t.test on what it loaded give the report's realism ANOVA and t-tests (1e-9), and the
    factorial ANOVA on rating_z gives the report's F per block."""
    rep = analyze(study, tmp_path / "r")
    out = subprocess.run([*CLI, "export", str(study), "--out", str(tmp_path / "x"), "--format",
                          "r"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    script = tmp_path / "x" / "check.R"
    script.write_text("""
suppressMessages(library(afex))
source("load.R")
r <- droplevels(d[d$protocol == "realism" & d$phase == "testing", ])
a <- anova(suppressMessages(aov_ez("participant", "rating", r, within = "sample",
                                   fun_aggregate = mean)), correction = "none")
cat("realism_F", sprintf("%.17g", a$F[1]), "\n")
cm <- tapply(r$rating, list(r$participant, r$sample), mean)
ok <- complete.cases(cm)
tt <- t.test(cm[ok, 1], cm[ok, 2], paired = TRUE)
cat("t", colnames(cm)[1], colnames(cm)[2], sprintf("%.17g", tt$statistic), "\n")
f <- d[d$protocol == "factorial", ]
for (b in unique(f$block)) {
  g <- droplevels(f[f$block == b & !is.na(f$rating_z), ])
  a <- anova(suppressMessages(aov_ez("participant", "rating_z", g,
             within = c("frequency", "decay", "slope"), fun_aggregate = mean)),
             correction = "none")
  cat("factorial", b, sprintf("%.17g", a["frequency", "F"]), "\n")
}
""")
    res = subprocess.run(["Rscript", "check.R"], cwd=script.parent, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.count("\n") >= 4 and not res.stderr.strip().startswith("'data.frame'")
    lines = [ln.split() for ln in res.stdout.splitlines()]
    realism = _analysis(rep, "realism/testing")
    fac = _analysis(rep, "factorial/rating")
    for ln in lines:
        if ln[0] == "realism_F":
            assert float(ln[1]) == pytest.approx(realism["anova"][0]["F"], rel=1e-9)
        elif ln[0] == "t":
            row = next(r for r in realism["pairwise"] if {r["A"], r["B"]} == {ln[1], ln[2]})
            sign = 1 if row["A"] == ln[1] else -1
            assert float(ln[3]) == pytest.approx(sign * row["t"], rel=1e-9)
        else:
            ref = {r["Source"]: r["F"] for r in fac["groups"][ln[1]]["anova"]}
            assert float(ln[2]) == pytest.approx(ref["frequency"], rel=1e-9)
    assert {ln[0] for ln in lines} == {"realism_F", "t", "factorial"}


def _chromium_shot(page, png, height=1200):
    out = subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu",
                          "--hide-scrollbars", "--virtual-time-budget=3000",
                          f"--screenshot={png}", f"--window-size=1280,{height}",
                          page.as_uri()], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and png.exists(), out.stderr[-2000:]


@pytest.mark.screen
@pytest.mark.slow
@pytest.mark.realtime(False)  # headless chromium keeps virtual time: with its module's study
def test_report_html_is_valid_and_reads_in_a_browser(study, tmp_path, artifacts):
    """report.html parsed strictly (every tag closed, no Markdown syntax leaking into the
    text, every figure shown and found), the same sections as report.md, and rendered
    by headless chromium: the first screen and the realism section are saved to
    tests/artifacts/screens/ (docs/screens/ via `make screens`) and are not blank."""
    import re
    from html.parser import HTMLParser

    import numpy as np
    from PIL import Image

    analyze(study, tmp_path / "r")
    page = tmp_path / "r" / "report.html"
    text = page.read_text()

    class Strict(HTMLParser):
        VOID = {"meta", "img", "br", "hr", "link", "input"}

        def __init__(self):
            super().__init__()
            self.stack, self.words, self.h2, self.images = [], [], [], []

        def handle_starttag(self, tag, attrs):
            if tag == "img":
                self.images.append(dict(attrs)["src"])
            if tag not in self.VOID:
                self.stack.append(tag)

        def handle_startendtag(self, tag, attrs):  # <img … />: a void element, closed
            assert tag in self.VOID, tag
            self.handle_starttag(tag, attrs)

        def handle_endtag(self, tag):
            assert self.stack and self.stack[-1] == tag, (tag, self.stack[-5:])
            self.stack.pop()

        def handle_data(self, data):
            self.words.append(data)
            if self.stack and self.stack[-1] == "h2":
                self.h2.append(data.strip())

    p = Strict()
    p.feed(text)
    p.close()
    assert p.stack == []
    # every figure the report made is shown, and every image shown is a file beside it
    # (a caption with parentheses once cut the path of two of eight)
    pngs = sorted(f.name for f in (tmp_path / "r").glob("*.png"))
    assert len(pngs) >= 8 and sorted(p.images) == pngs
    body = " ".join(p.words)
    for leak in ("**", "| ---", "_none_", "![", "\\|"):
        assert leak not in body, leak
    md = (tmp_path / "r" / "report.md").read_text()
    assert p.h2 == [h[3:].strip() for h in md.splitlines() if h.startswith("## ")]
    assert p.h2[0] == "Summary of findings" and p.h2[-1] == "Appendix"
    assert re.search(r"F\(\d", body)  # the summary's APA-style test
    assert "p < .001" in body or "p = ." in body
    shots = artifacts / "screens"
    shots.mkdir(parents=True, exist_ok=True)
    _chromium_shot(page, shots / "report-first-screen.png")
    start = text.index('<h2 id="realism-testing">')
    cut = tmp_path / "r" / "report-realism.html"
    cut.write_text(text[:text.index("<body>") + 6] + text[start:])
    _chromium_shot(cut, shots / "report-realism.png")
    for name in ("report-first-screen", "report-realism"):
        img = np.asarray(Image.open(shots / f"{name}.png").convert("L"), float)
        assert img.std() > 20, name  # text and tables, not an empty page
