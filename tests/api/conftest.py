"""Server fixtures for the tests that use the built-in sample project: one app per test
module on a copy of the sample data dir (`sample_data_dir`, built once per run). Modules
that test an empty or differently limited server make their own app."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient


@pytest.fixture(scope="module")
def app(tmp_path_factory, sample_data_dir):
    """A server app whose data dir holds the sample project (mesh, landmarks, rig)."""
    import shutil

    from server.app import create_app

    folder = tmp_path_factory.mktemp("data") / "data"
    shutil.copytree(sample_data_dir, folder)
    return create_app(folder)


@pytest.fixture(scope="module")
def client(app):
    with TestClient(app) as c:
        yield c


@pytest.fixture(scope="module")
def sample_id(app) -> str:
    """The sample project's id."""
    with TestClient(app) as c:
        return next(p["id"] for p in c.get("/api/projects").json() if p["settings"].get("sample"))
