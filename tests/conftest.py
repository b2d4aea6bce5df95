"""Shared test settings."""

import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("ci", deadline=None, max_examples=60,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci")

ROOT = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    """Build transient libraries into a fresh cache per run (subprocesses inherit it)."""
    if "HAPTICLAB_CACHE" not in os.environ:
        os.environ["HAPTICLAB_CACHE"] = tempfile.mkdtemp(prefix="hapticlab-cache-")


@pytest.fixture(scope="session")
def artifacts() -> Path:
    """Folder for files tests leave behind for people to look at (screenshots, plots)."""
    path = ROOT / "tests" / "artifacts"
    path.mkdir(parents=True, exist_ok=True)
    return path
