"""A transient library file that is not one is named for what it is, and a named pipe or
a folder where a library belongs never blocks the command that reads it (`library show`,
and every run that plays a matched sample)."""

import os
import signal

import pytest

from device.matching.library import LibraryError, TransientLibrary


@pytest.fixture
def deadline():
    """Fail in 5 s instead of blocking: opening a named pipe waits for a writer forever."""
    def expired(signum, frame):
        raise TimeoutError("reading the library blocked")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(5)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


def test_a_named_pipe_is_refused_without_blocking(tmp_path, deadline):
    os.mkfifo(tmp_path / "lib.npz")
    with pytest.raises(LibraryError, match=r"lib.npz: not a regular file \(a named pipe\)"):
        TransientLibrary.load(tmp_path / "lib.npz")


def test_a_folder_is_named_as_a_folder(tmp_path):
    (tmp_path / "lib.npz").mkdir()
    with pytest.raises(LibraryError, match=r"lib.npz: not a regular file \(a directory\)"):
        TransientLibrary.load(tmp_path / "lib.npz")


def test_a_text_file_is_not_said_to_hold_pickled_data(tmp_path):
    (tmp_path / "lib.npz").write_text("velocities,forces\n0.1,2\n")
    with pytest.raises(LibraryError) as err:
        TransientLibrary.load(tmp_path / "lib.npz")
    assert "not a NumPy .npz archive" in str(err.value)
    assert "pickled" not in str(err.value)
