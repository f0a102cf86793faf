"""Project names are unique per data dir (issue 13 item 5): a second "Untitled 1", a .glb
imported beside the project it was exported from, or a rename onto a taken name get the
first free " (k)" suffix; a project keeps its own name when renamed to it."""

import pytest
from fastapi.testclient import TestClient

from server.app import create_app


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(tmp_path_factory.mktemp("data"))) as c:
        yield c


def _create(client, name):
    r = client.post("/api/projects", json={"name": name})
    assert r.status_code == 201, r.text
    return r.json()


def test_created_names_are_made_unique(client):
    first, second, third = (_create(client, "Untitled 1") for _ in range(3))
    assert [first["name"], second["name"], third["name"]] == ["Untitled 1", "Untitled 1 (2)", "Untitled 1 (3)"]
    names = [p["name"] for p in client.get("/api/projects").json()]
    assert len(names) == len(set(names))


def test_a_rename_onto_a_taken_name_is_made_unique_and_a_project_keeps_its_own(client):
    a, b = _create(client, "Alpha"), _create(client, "Beta")
    renamed = client.patch(f"/api/projects/{b['id']}", json={"name": "Alpha"}).json()
    assert renamed["name"] == "Alpha (2)"
    assert client.patch(f"/api/projects/{a['id']}", json={"name": "Alpha"}).json()["name"] == "Alpha"
    assert client.patch(f"/api/projects/{b['id']}", json={"name": "Alpha (2)"}).json()["name"] == "Alpha (2)"


def test_a_glb_imported_beside_its_source_gets_its_own_name(client):
    sample = next(p for p in client.get("/api/projects").json() if p["rig"])
    data = client.get(f"/api/projects/{sample['id']}/export.glb").content
    names = []
    for _ in range(2):
        r = client.post("/api/projects/import", files={"file": (f"{sample['name']}.glb", data)})
        assert r.status_code == 201, r.text
        names.append(r.json()["project"]["name"])
    assert names == [f"{sample['name']} (2)", f"{sample['name']} (3)"]
