"""What every test folder shares: the built-in sample project built once per run (waits
for jobs and the timeout scale are in `tests.waits`).

Folders: ``unit/`` tests the library (`retarget`), ``api/`` the server in process
(FastAPI's TestClient, the isolation children, the wire formats), ``e2e/`` a real server on
a real port driven by Chromium, ``js/`` holds the Node scripts some of them run.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from tests.file_seconds import file_seconds, longest_first


def pytest_xdist_auto_num_workers(config) -> int:
    """``-n auto``: one worker more than the cores. The suite computes for less than half of
    its time (on 2 cores: 638 CPU s in 744 s); the rest is real time (videos and the webcam
    played at their rate, countdowns, streams), which a third worker fills: 620 s against
    664 s for the tests on this 2-core machine."""
    return (os.cpu_count() or 1) + 1


def pytest_collection_modifyitems(config, items) -> None:
    """The longest test files first (`tests.file_seconds`; with ``--no-loadscope-reorder``
    xdist hands the files out in this order)."""
    longest_first(items, file_seconds())


@pytest.fixture(scope="session")
def sample_data_dir(tmp_path_factory) -> Path:
    """A server data dir holding only the built-in sample project (mesh, landmarks and
    rig), built once per run; copy it (`copy_sample_data`) rather than use it."""
    from server.sample import ensure_sample_project
    from server.store import ProjectStore

    folder = tmp_path_factory.mktemp("sample") / "data"
    store = ProjectStore(folder)
    try:
        assert ensure_sample_project(store) is not None
    finally:
        store.close()
    shutil.rmtree(folder / "scratch", ignore_errors=True)
    return folder


@pytest.fixture
def copy_sample_data(sample_data_dir):
    """A function: `copy_sample_data(dest)` makes `dest` a fresh data dir holding the
    sample project, as a server started on an empty data dir would make it."""
    def copy(dest: Path) -> Path:
        shutil.copytree(sample_data_dir, dest)
        return dest
    return copy
