"""Every `hapticlab bench` option's bad value is a named error before anything runs (issue
53, item 8): the value, the option, and what it takes — never a traceback, never silently
replaced by something else."""

import subprocess
import sys

import pytest

from app.api import benchmark
from app.errors import UsageError

CLI = [sys.executable, "-m", "app"]


@pytest.mark.parametrize("what, options, words", [
    ("sim", {"repeats": 0}, "--repeats 0: a whole number >= 1"),
    ("sim", {"repeats": -3}, "--repeats -3: a whole number >= 1"),
    ("analysis", {"repeats": 2.5}, "--repeats 2.5: a whole number >= 1"),
    ("link", {"fuzz": -1}, "--fuzz -1: a whole number >= 0"),
    ("crash", {"kills": 0}, "--kills 0: a whole number >= 1"),
    ("crash", {"points": "3,x"}, "--points '3,x': all, or point numbers"),
    ("crash", {"points": "0"}, "--points '0': all, or point numbers"),
    ("crash", {"points": ","}, "--points ',': all, or point numbers"),
    ("crash", {"boundaries": "0"}, "--boundaries '0': all, or row numbers >= 1"),
    ("crash", {"boundaries": "all", "points": "all"}, "--points and --boundaries are "
                                                       "different crash benchmarks"),
    ("crash", {"kills": 5, "points": "all"}, "--kills and --points are different crash"),
    ("sim", {"boundaries": "all"}, "bench sim does not read --boundaries (crash does)"),
    ("orderings", {"seeds": "1,a"}, "--seeds '1,a': whole numbers"),
    ("link", {"firmware": "arm"}, "--firmware 'arm': one of host, qemu"),
    ("link", {"load": "1,two"}, "--load '1,two': competing processes"),
    ("link", {"load": "-1"}, "--load '-1': competing processes"),
    ("link", {"load": "0", "targets": "python,fpga"}, "--targets 'python,fpga': unknown fpga"),
    ("link", {"load": "0", "seconds": 0.0}, "--seconds 0: a number of seconds > 0"),
    ("link", {"load": "0", "seconds": float("nan")}, "--seconds nan: a number of seconds"),
    ("link", {"load": "0", "seconds": float("inf")}, "--seconds inf: a number of seconds"),
    # an option the benchmark does not read is not silently dropped
    ("sim", {"kills": 5}, "bench sim does not read --kills (crash does)"),
    ("crash", {"load": "0"}, "bench crash does not read --load (link does)"),
    ("link", {"seconds": 5.0}, "--seconds is read only with --load"),
    ("energy", {"seeds": "1"}, "bench energy does not read --seeds (causes, factorial, "
                               "orderings, thresholds do)"),
    ("crash", {"sessions": 5}, "bench crash does not read --sessions (thresholds does)"),
    ("thresholds", {"sessions": 0}, "--sessions 0: a whole number >= 1"),
])
def test_a_bad_option_value_is_named_before_anything_runs(what, options, words):
    with pytest.raises(UsageError) as err:
        benchmark(what, **options)
    assert words in str(err.value)


@pytest.mark.integration
def test_the_command_line_says_it_in_one_line(tmp_path):
    out = subprocess.run([*CLI, "bench", "link", "--load", "1,two"], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert out.stderr.startswith("hapticlab: error: --load '1,two'")


@pytest.mark.integration
@pytest.mark.slow
def test_crash_points_beyond_the_sessions_write_points_say_how_many_there_are(tmp_path):
    """The number of write points is known once the reference session has run: a point
    beyond it is named with the count (it was an IndexError)."""
    from benchmarks.crash import kill_at_points

    proto = tmp_path / "mini.toml"
    from pathlib import Path

    proto.write_text((Path(__file__).resolve().parents[1] / "data" / "mini.toml").read_text())
    with pytest.raises(UsageError, match=r"--points 2,99999: point 99999 is beyond this "
                                         r"session's \d+ write points \(1\.\.\d+\)"):
        kill_at_points(protocol=str(proto), points="2,99999", workdir=tmp_path / "w",
                       traces="none")


@pytest.mark.integration
@pytest.mark.slow
def test_crash_boundaries_beyond_the_sessions_rows_say_how_many_there_are(tmp_path):
    from benchmarks.crash import resume_after_rows

    proto = tmp_path / "mini.toml"
    from pathlib import Path

    proto.write_text((Path(__file__).resolve().parents[1] / "data" / "mini.toml").read_text())
    with pytest.raises(UsageError, match=r"--boundaries 1,99999: row 99999 is beyond this "
                                         r"session's \d+ rows a cut can follow \(1\.\.\d+\)"):
        resume_after_rows(protocol=str(proto), rows="1,99999", workdir=tmp_path / "w")
