"""The tier guard (tests/tiers.py): a test without a tier's marker is in the unit tier, and
fails when it starts a process, opens a pseudo-terminal or takes seconds; a test marked for
what it does is left alone. Each case runs in a pytest session of its own, in this process,
on a test file written here."""

import textwrap

import pytest

from .tiers import TierGuard

#: the inner sessions' tiers, as pyproject.toml declares them (a subset is enough)
INI = """[pytest]
addopts = --strict-markers --import-mode=importlib
markers =
    integration: starts a process
    slow: takes seconds
    unit: given by the guard
    realtime: not a tier
"""

# the cases start `true` and a pytest session each
pytestmark = [pytest.mark.integration]


class _Outcomes:
    """A plugin that keeps each test's outcome and failure text by test name."""

    def __init__(self):
        self.got: dict[str, tuple[str, str]] = {}

    def pytest_runtest_logreport(self, report):
        name = report.nodeid.split("::")[-1]
        if report.when == "call" or report.failed:
            self.got[name] = (report.outcome, str(report.longrepr or ""))


def _run(tmp_path, source: str, *args: str, budget_s: float = 4.0) -> dict:
    """Run the tests in ``source`` under the guard; {test name: (outcome, failure text)}."""
    (tmp_path / "pytest.ini").write_text(INI)
    (tmp_path / f"test_{tmp_path.name}.py").write_text(textwrap.dedent(source))
    outcomes = _Outcomes()

    class Guard:
        def pytest_configure(self, config):
            config.pluginmanager.register(TierGuard(config, budget_s=budget_s), "tier-guard")

    pytest.main([str(tmp_path), "-q", "-p", "no:cacheprovider", "--rootdir", str(tmp_path),
                 "-c", str(tmp_path / "pytest.ini"), *args], plugins=[Guard(), outcomes])
    return outcomes.got


def test_an_unmarked_test_that_starts_a_process_fails_and_says_which_mark(tmp_path):
    got = _run(tmp_path, """
        import subprocess
        import pytest

        def test_unmarked():
            subprocess.run(["true"], check=True)

        @pytest.mark.integration
        def test_marked():
            subprocess.run(["true"], check=True)
        """)
    outcome, text = got["test_unmarked"]
    assert outcome == "failed" and "started a process" in text and "'true'" in text, text
    assert "Mark it `integration`" in text
    assert got["test_marked"][0] == "passed"


def test_a_process_started_by_a_fixture_of_any_scope_counts(tmp_path):
    got = _run(tmp_path, """
        import subprocess
        import pytest

        @pytest.fixture(scope="module")
        def server():
            return subprocess.Popen(["sleep", "0"]).wait()

        def test_uses_it(server):
            assert server == 0
        """)
    outcome, text = got["test_uses_it"]
    assert outcome == "failed" and "started a process" in text, text


def test_a_pseudo_terminal_counts(tmp_path):
    got = _run(tmp_path, """
        import os

        def test_opens_one():
            master, slave = os.openpty()
            os.close(master)
            os.close(slave)
        """)
    outcome, text = got["test_opens_one"]
    assert outcome == "failed" and "os.openpty()" in text, text


def test_an_unmarked_test_over_the_budget_fails_and_a_slow_one_does_not(tmp_path):
    got = _run(tmp_path, """
        import time
        import pytest

        def test_waits():
            time.sleep(0.3)

        @pytest.mark.slow
        def test_waits_and_says_so():
            time.sleep(0.3)

        def test_quick():
            assert sum(range(10)) == 45
        """, budget_s=0.2)
    outcome, text = got["test_waits"]
    assert outcome == "failed" and "over the unit tier's 0.2 s" in text, text
    assert "mark it `slow`" in text
    assert got["test_waits_and_says_so"][0] == "passed"
    assert got["test_quick"][0] == "passed"


def test_a_failing_test_keeps_its_own_failure(tmp_path):
    got = _run(tmp_path, """
        import subprocess

        def test_fails_first():
            subprocess.run(["true"])
            assert 1 == 2, "its own reason"
        """)
    outcome, text = got["test_fails_first"]
    assert outcome == "failed" and "its own reason" in text and "started a process" not in text


def test_the_unit_tier_is_selected_by_its_marker(tmp_path):
    source = """
        import pytest

        def test_plain():
            pass

        @pytest.mark.slow
        def test_slow():
            pass

        @pytest.mark.realtime
        def test_realtime_alone_is_no_tier():
            pass
        """
    assert set(_run(tmp_path, source, "-m", "unit")) == {"test_plain",
                                                          "test_realtime_alone_is_no_tier"}
    assert set(_run(tmp_path, source, "-m", "not unit")) == {"test_slow"}


class _Item:
    """What :func:`tests.conftest.is_realtime` reads of a collected test."""

    def __init__(self, *marks, fixtures=()):
        self.marks = {m.name: m for m in (getattr(pytest.mark, n) if isinstance(n, str) else n
                                          for n in marks)}
        self.fixturenames = list(fixtures)

    def get_closest_marker(self, name):
        mark = self.marks.get(name)
        return mark.mark if mark is not None else None


def test_a_test_is_real_time_by_its_tier_or_fixture_unless_it_says_it_has_no_deadline():
    from .conftest import is_realtime

    assert not is_realtime(_Item("slow", "integration"))
    assert is_realtime(_Item("screen"))
    assert is_realtime(_Item("firmware", "slow"))
    assert is_realtime(_Item(fixtures=("tmp_path", "emulator")))
    assert is_realtime(_Item(pytest.mark.realtime))
    assert not is_realtime(_Item("screen", pytest.mark.realtime(False)))
    # a device or a display fixture is real time whatever the test says
    assert is_realtime(_Item("screen", pytest.mark.realtime(False), fixtures=("emulator",)))
    assert is_realtime(_Item("integration", pytest.mark.realtime(True)))
