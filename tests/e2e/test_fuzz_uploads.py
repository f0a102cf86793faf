"""Fuzzed uploads through a real `retarget serve`: damaged files of every format the
server reads, each sent to its route, must be answered 2xx or 4xx with a reason, never
5xx or a dropped connection, and the server must stay up and leave other projects alone.

One server serves the whole module. Seeds and mutators are `tests.hostile_inputs`
(fixed seeds, so a failure names a reproducible mutant: its format, index and label).
Takes go to a project imported from an exported .glb (68 iBUG landmarks, so a take is
also checked against the layout), meshes to an empty project, imports to the import
route; the sample project is only read, and must be unchanged at the end.
`bench/hostile.py` runs the same fuzz at hundreds of mutants per format.
"""

from __future__ import annotations

import faulthandler
import hashlib
import json
import multiprocessing
import random
import resource
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import pytest

from tests.e2e.conftest import Server, sample_copy
from tests.hostile_inputs import (
    MESH_EXTENSIONS,
    TAKE_EXTENSIONS,
    answer_fault,
    c3d_seed,
    c3d_two_bytes,
    import_seed,
    mesh_seeds,
    mutants,
    send_upload,
    take_seeds,
)

TAKE_MUTANTS = 30
MESH_MUTANTS = 20
IMPORT_MUTANTS = 20
RNG_SEED = 20261201
CRASH_SEARCH = 400  # C3D mutants tried directly on ezc3d, at most
CRASH_WANTED = 3


@dataclass
class Fuzz:
    """The module's server and what the tests share: a client, the sample project's id
    and state when the server started, and the projects uploads go to."""

    server: Server
    client: httpx.Client
    sample_id: str
    sample_before: dict
    take_project: str = ""
    mesh_project: str = ""
    seeds: dict = field(default_factory=dict)

    def log_tail(self) -> str:
        return self.server.log.read_text(errors="replace")[-3000:] if self.server.log else ""

    def assert_up(self, after: str) -> None:
        """The server process is alive and lists its projects."""
        assert self.server.process.poll() is None, \
            f"the server died (exit {self.server.process.returncode}) after {after}:\n{self.log_tail()}"
        reply = self.client.get("/api/projects")
        assert reply.status_code == 200, f"GET /api/projects answered {reply.status_code} after {after}"

    def fuzz(self, seed, count: int, project: str | None) -> dict:
        """Send `count` mutants of `seed`; fail listing every improper answer. Stored
        takes and imported projects are deleted again. Returns the status counts."""
        faults, counts = [], {}
        for mutant in mutants(seed, count, RNG_SEED):
            where = f"{seed.kind} .{seed.ext} mutant {mutant.index} ({mutant.label})"
            try:
                reply = send_upload(self.client, seed.kind, project, mutant.filename,
                                    mutant.data, mutant.form)
            except httpx.TransportError as exc:
                faults.append(f"{where}: connection error {type(exc).__name__}: {exc}")
                if self.server.process.poll() is not None:
                    break
                continue
            counts[reply.status_code] = counts.get(reply.status_code, 0) + 1
            fault = answer_fault(reply)
            if fault is not None:
                faults.append(f"{where}: {fault}")
            elif reply.status_code in (200, 201):
                self._forget(seed.kind, project, reply.json())
        assert not faults, ("improper answers:\n" + "\n".join(faults)
                            + f"\n--- server log tail ---\n{self.log_tail()}")
        self.assert_up(f"the .{seed.ext} {seed.kind} mutants")
        return counts

    def _forget(self, kind: str, project: str | None, answer: dict) -> None:
        if kind == "take":
            self.client.delete(f"/api/projects/{project}/takes/{answer['id']}")
        elif kind == "import":
            self.client.delete(f"/api/projects/{answer['project']['id']}")


def sample_state(client: httpx.Client, sample_id: str) -> dict:
    """Everything of the sample project a fuzzed upload might disturb (digests of the
    binary answers)."""
    state = {"project": client.get(f"/api/projects/{sample_id}").json(),
             "landmarks": client.get(f"/api/projects/{sample_id}/landmarks").json(),
             "rig": client.get(f"/api/projects/{sample_id}/rig").json(),
             "takes": client.get(f"/api/projects/{sample_id}/takes").json()}
    for path in ("mesh", "mesh/arrays", "rig/weights"):
        reply = client.get(f"/api/projects/{sample_id}/{path}")
        assert reply.status_code == 200, (path, reply.text)
        state[path] = hashlib.sha256(reply.content).hexdigest()
    return state


@pytest.fixture(scope="module")
def fuzz(tmp_path_factory, sample_data_dir):
    server = Server(sample_copy(sample_data_dir, tmp_path_factory.mktemp("fuzz") / "data")).start()
    client = httpx.Client(base_url=server.url, timeout=120)
    try:
        (sample,) = [p for p in client.get("/api/projects").json() if p["name"] == "Sample face"]
        state = Fuzz(server, client, sample["id"], sample_state(client, sample["id"]))
        state.seeds = {"take": take_seeds(), "mesh": mesh_seeds(), "import": import_seed()}
        imported = send_upload(client, "import", None, "fuzz-takes.glb", state.seeds["import"].data)
        assert imported.status_code == 201, imported.text
        state.take_project = imported.json()["project"]["id"]
        state.mesh_project = client.post("/api/projects", json={"name": "fuzz meshes"}).json()["id"]
        # every seed is valid: the fuzz starts from files the server takes
        for ext, seed in state.seeds["take"].items():
            reply = send_upload(client, "take", state.take_project, seed.filename, seed.data, seed.form)
            assert reply.status_code == 201, (ext, reply.text)
            client.delete(f"/api/projects/{state.take_project}/takes/{reply.json()['id']}")
        for ext, seed in state.seeds["mesh"].items():
            reply = send_upload(client, "mesh", state.mesh_project, seed.filename, seed.data)
            assert reply.status_code == 200, (ext, reply.text)
        yield state
    finally:
        client.close()
        server.stop()


@pytest.mark.parametrize("ext", TAKE_EXTENSIONS)
def test_fuzzed_take_files_are_refused_with_a_reason(fuzz, ext):
    counts = fuzz.fuzz(fuzz.seeds["take"][ext], TAKE_MUTANTS, fuzz.take_project)
    assert sum(counts.values()) == TAKE_MUTANTS


@pytest.mark.parametrize("ext", MESH_EXTENSIONS)
def test_fuzzed_mesh_files_are_refused_with_a_reason(fuzz, ext):
    counts = fuzz.fuzz(fuzz.seeds["mesh"][ext], MESH_MUTANTS, fuzz.mesh_project)
    assert sum(counts.values()) == MESH_MUTANTS


def test_fuzzed_project_imports_are_refused_with_a_reason(fuzz):
    counts = fuzz.fuzz(fuzz.seeds["import"], IMPORT_MUTANTS, None)
    assert sum(counts.values()) == IMPORT_MUTANTS


@pytest.mark.parametrize("name, ext", [("mapping", "csv"), ("labelled_vertices", "glb")])
def test_take_form_fields_nested_200k_deep_are_refused_with_a_reason(fuzz, name, ext):
    seed = fuzz.seeds["take"][ext]
    form = {**seed.form, name: "[" * 200_000 + "]" * 200_000}
    reply = send_upload(fuzz.client, "take", fuzz.take_project, f"deep.{ext}", seed.data, form)
    assert reply.status_code == 422, (reply.status_code, reply.text, fuzz.log_tail())
    assert name in reply.json()["detail"]
    fuzz.assert_up(f"form field {name!r} nested 200,000 deep")


# --- C3D files that crash ezc3d ----------------------------------------------------------------

def _parse_each(paths: list[str], start: int, conn) -> None:
    """Child: ezc3d on paths[start:], sending each index before parsing it (so the
    parent knows which file a crash was on), then -1."""
    import ezc3d

    faulthandler.disable()  # pytest's would print every expected crash
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (min(4 << 30, hard) if hard > 0 else 4 << 30, hard))
    for i in range(start, len(paths)):
        conn.send(i)
        try:
            ezc3d.c3d(paths[i])
        except Exception:  # noqa: BLE001 - a refusal is not what is looked for
            pass
    conn.send(-1)


def ezc3d_crashers(folder: Path, limit: int = CRASH_SEARCH, wanted: int = CRASH_WANTED,
                   rng_seed: int = 0) -> tuple[list[tuple[bytes, str, str]], int]:
    """([(bytes, label, signal)], mutants tried): C3D mutants (two random bytes, as in
    the audit) that kill the process parsing them with `ezc3d.c3d`, found in throwaway
    forked children, at most `wanted` of the first `limit`."""
    rng = random.Random(rng_seed)
    seed = c3d_seed().data
    made = [c3d_two_bytes(seed, rng) for _ in range(limit)]
    paths = []
    for i, (_, data) in enumerate(made):
        path = folder / f"m{i:04d}.c3d"
        path.write_bytes(data)
        paths.append(str(path))
    context = multiprocessing.get_context("fork")
    found, start, tried = [], 0, 0
    while start < limit and len(found) < wanted:
        receive, send = context.Pipe(duplex=False)
        child = context.Process(target=_parse_each, args=(paths, start, send), daemon=True)
        child.start()
        send.close()
        last, finished = None, False
        while True:
            if not receive.poll(20):  # a mutant that makes ezc3d loop: skip it
                child.kill()
                break
            try:
                message = receive.recv()
            except EOFError:
                break
            if message == -1:
                finished = True
                break
            last = message
        child.join(10)
        receive.close()
        tried = limit if finished else (last or 0) + 1
        if last is not None and not finished and child.exitcode is not None and child.exitcode < 0:
            import signal

            name = signal.Signals(-child.exitcode).name
            if name != "SIGKILL":
                found.append((made[last][1], made[last][0], name))
        if finished or last is None:
            break
        start = last + 1
    return found, tried


def test_c3d_files_that_crash_ezc3d_are_refused_and_the_server_streams_on(fuzz):
    with tempfile.TemporaryDirectory() as folder:
        crashers, tried = ezc3d_crashers(Path(folder))
    assert crashers, (f"none of {tried} two-byte C3D mutants crashed ezc3d in this version: the "
                      "test no longer shows the isolation saving the server from a native crash; "
                      "search more mutants or another mutation")
    for i, (data, label, signal_name) in enumerate(crashers):
        reply = send_upload(fuzz.client, "take", fuzz.take_project, f"crash-{i}.c3d", data)
        assert reply.status_code == 422, (label, signal_name, reply.status_code, reply.text,
                                          fuzz.log_tail())
        detail = reply.json()["detail"]
        assert f"crash-{i}.c3d" in detail and "not a readable c3d file" in detail.lower(), detail
        fuzz.assert_up(f"C3D mutant {label} (ezc3d {signal_name})")
    from websockets.sync.client import connect

    url = fuzz.server.url.replace("http://", "ws://") + f"/api/projects/{fuzz.sample_id}/stream"
    with connect(url, open_timeout=30) as ws:
        hello = json.loads(ws.recv(timeout=30))
    assert hello["type"] == "hello" and hello["project"] == fuzz.sample_id
    assert hello["n_points"] == 68


def test_the_sample_project_is_unchanged(fuzz):
    fuzz.assert_up("the fuzz")
    assert sample_state(fuzz.client, fuzz.sample_id) == fuzz.sample_before
