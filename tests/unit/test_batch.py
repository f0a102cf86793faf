"""`retarget batch` (retarget/batch/): the manifest's checks, and a generated batch of 3
characters (two as mesh + landmarks, one as an exported project) x 4 takes (CSV, NPY,
JSON and a broken CSV) run in one process and on a 2-worker Dask LocalCluster: the same
bytes, the broken take's pairs failed with the reason, a rerun doing nothing, a changed
take setting redoing only its pairs, a worker killed mid-run survived."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest
import yaml

from retarget.batch import INDEX_NAME, plan_batch, read_manifest, run_batch
from retarget.batch.manifest import manifest_from_dict
from retarget.cli import main
from retarget.errors import RetargetError
from retarget.testing.batch_manifest import write_batch_fixture

GOOD = {f"{c}/take{k}" for c in ("wide", "narrow", "lips") for k in range(3)}
BROKEN = {f"{c}/broken" for c in ("wide", "narrow", "lips")}


@pytest.fixture(scope="module")
def manifest_path(tmp_path_factory) -> Path:
    return write_batch_fixture(tmp_path_factory.mktemp("batch-in"), n_frames=20)


@pytest.fixture(scope="module")
def reference(manifest_path, tmp_path_factory) -> Path:
    """The single-process run's output root."""
    out = tmp_path_factory.mktemp("batch-here")
    report = run_batch(plan_batch(read_manifest(manifest_path), out), workers=0)
    assert set(report.succeeded) == GOOD and set(report.failed) == BROKEN
    return out


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# ---------------------------------------------------------------------------------------
# the manifest


def _minimal(**changes) -> dict:
    data = {"characters": [{"name": "a", "mesh": "a.obj", "landmarks": "a.json"}],
            "takes": [{"name": "t", "file": "t.csv"}]}
    for key, value in changes.items():
        if key in ("character", "take"):
            data[key + "s"] = [{**data[key + "s"][0], **value}]
        else:
            data[key] = value
    return data


@pytest.mark.parametrize("data, message", [
    ([1, 2], "must be a mapping"),
    (_minimal(extra=1), "unknown key(s) 'extra'"),
    (_minimal(outputs=["gif"]), "outputs must be a list of gltf"),
    (_minimal(characters=[]), "'characters' must be a non-empty list"),
    (_minimal(character={"name": "../up"}), "characters[0] ('../up'): 'name' must be"),
    (_minimal(character={"project": "p.glb"}), "characters[0] ('a'): give a 'project'"),
    (_minimal(character={"rig": {"deformer": "magic"}}), "characters[0] ('a'): unknown deformer 'magic'"),
    (_minimal(character={"rig": {"k": 0}}), "rig k must be a positive integer"),
    (_minimal(character={"layout": "ibug99"}), "unknown layout 'ibug99'"),
    (_minimal(take={"settings": {"filter": "wobbly"}}), "takes[0] ('t'): settings: settings filter"),
    (_minimal(take={"fps": -3}), "takes[0] ('t'): fps must be a positive number"),
    (_minimal(takes=[{"name": "t", "file": "a.csv"}, {"name": "t", "file": "b.csv"}]), "'t' is used twice"),
    (_minimal(pairs=[{"character": "a", "take": "nope"}]), "pairs[0]: no take named 'nope'"),
    (_minimal(gltf={"form": "joints"}), "gltf: form must be one of exact, skin"),
    (_minimal(gltf={"rate": 29.97}), "gltf: the animation rate must be one of 24, 25, 30, 60"),
    (_minimal(gltf={"key_tolerance": -1}), "gltf: the key tolerance must be a number of millimetres"),
    (_minimal(gltf={"scale": 2}), "gltf: unknown key(s) 'scale'"),
    (_minimal(gltf=[1]), "gltf must be a mapping"),
])
def test_manifest_errors_name_the_entry(data, message, tmp_path):
    with pytest.raises(RetargetError) as error:
        manifest_from_dict(data, tmp_path)
    assert message in str(error.value)


def test_manifest_paths_are_relative_to_it(manifest_path):
    manifest = read_manifest(manifest_path)
    assert [c.name for c in manifest.characters] == ["wide", "narrow", "lips"]
    assert manifest.characters[2].project == manifest_path.parent / "lips.glb"
    assert manifest.take("take1").file == manifest_path.parent / "take1.npy"
    assert len(manifest.pairs) == 12 and manifest.outputs == ("gltf", "arkit_csv", "npy")


def test_cli_refuses_a_bad_manifest(tmp_path, capsys):
    bad = tmp_path / "m.json"
    bad.write_text('{"characters": 3}')
    assert main(["batch", str(bad), "--out", str(tmp_path / "out"), "--workers", "0"]) == 2
    assert "'characters' must be a non-empty list" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------
# running


def test_single_process_tree(reference):
    files = _files(reference)
    expected = {f"{pair}/{name}" for pair in GOOD for name in ("animation.glb", "arkit.csv", "vertices.npy")}
    assert set(files) == expected | {INDEX_NAME}
    assert not any(name.endswith(".tmp") for name in files)


def test_cluster_gives_the_same_bytes(manifest_path, reference, client, tmp_path):
    from distributed import get_task_stream

    with get_task_stream(client) as stream:
        report = run_batch(plan_batch(read_manifest(manifest_path), tmp_path), client=client)
    keys = [task["key"] for task in stream.data]
    assert sum(key.startswith("character-") for key in keys) == 3  # a rig once per character
    assert sum(key.startswith("pair-") for key in keys) == 12
    assert set(report.succeeded) == GOOD
    assert set(report.failed) == BROKEN
    assert all("broken.csv" in reason for reason in report.failed.values())
    assert _files(tmp_path) == _files(reference)  # the index too


def test_rerun_does_nothing(manifest_path, reference):
    plan = plan_batch(read_manifest(manifest_path), reference)
    assert plan.jobs == [] and set(plan.skipped) == GOOD and set(plan.failed_before) == BROKEN
    report = run_batch(plan, workers=0)
    assert report.succeeded == [] and set(report.failed_before) == BROKEN
    assert plan_batch(read_manifest(manifest_path), reference, retry_failed=True).jobs != []


def test_changed_take_setting_redoes_only_its_pairs(manifest_path, reference, tmp_path):
    data = yaml.safe_load(manifest_path.read_text())
    data["takes"][1]["settings"] = {"filter": "mean3"}
    changed = manifest_path.parent / "changed.yaml"
    changed.write_text(yaml.safe_dump(data))
    plan = plan_batch(read_manifest(changed), reference)
    assert {job.key for job in plan.jobs} == {f"{c}/take1" for c in ("wide", "narrow", "lips")}


def test_gltf_options_shape_the_glb_and_redo_the_pairs_they_change(manifest_path, reference, tmp_path):
    """``gltf: {form: skin, rate: 24, key_tolerance: 0.05}``: every pair's .glb becomes a
    four-joint skin keyed at 24 fps (what the exporter records), and the changed option
    redoes every pair that writes a .glb, only those options' digests differing."""
    from retarget.gltf.document import GltfDocument

    data = yaml.safe_load(manifest_path.read_text())
    data["gltf"] = {"form": "skin", "rate": 24, "key_tolerance": 0.05}
    data["pairs"] = [{"character": "wide", "take": "take1"}]
    changed = manifest_path.parent / "small-gltf.yaml"
    changed.write_text(yaml.safe_dump(data))
    plan = plan_batch(read_manifest(changed), reference)
    assert [job.key for job in plan.jobs] == ["wide/take1"]   # done before, with other options
    report = run_batch(plan_batch(read_manifest(changed), tmp_path), workers=0)
    assert report.succeeded == ["wide/take1"]
    record = GltfDocument((tmp_path / "wide/take1/animation.glb").read_bytes(), "glb", None) \
        .doc.scenes[0].extras["retarget"]
    assert record["rate"] == 24.0 and record["key_tolerance_mm"] == 0.05 and "rms_relative" in record["fit"]
    assert len((tmp_path / "wide/take1/animation.glb").read_bytes()) < \
        len((reference / "wide/take1/animation.glb").read_bytes())


def test_cli_runs_a_batch(manifest_path, tmp_path, capsys):
    assert main(["batch", str(manifest_path), "--out", str(tmp_path), "--no-dask", "-q"]) == 1
    out = capsys.readouterr().out
    assert "9 succeeded, 3 failed" in out and "failed wide/broken" in out
    assert main(["batch", str(manifest_path), "--out", str(tmp_path), "--no-dask", "-q"]) == 1
    assert "0 succeeded, 0 failed and 3 as before, 9 skipped" in capsys.readouterr().out


def test_killed_worker_is_survived(manifest_path, reference, client, tmp_path):
    pids = client.run(os.getpid)  # worker address -> its process, which this test's cluster started
    killed = []

    def kill_one_busy(result) -> None:
        if killed:
            return
        busy = [address for address, keys in client.processing().items() if keys and address in pids]
        if busy:
            os.kill(pids[busy[0]], signal.SIGKILL)  # mid-task: the nanny starts a new worker
            killed.append(busy[0])

    report = run_batch(plan_batch(read_manifest(manifest_path), tmp_path), client=client,
                       on_result=kill_one_busy)
    assert killed, "no worker was busy to kill"
    assert set(report.succeeded) == GOOD and set(report.failed) == BROKEN
    assert _files(tmp_path) == _files(reference)


def test_missing_mesh_fails_only_its_pairs(manifest_path, tmp_path):
    data = yaml.safe_load(manifest_path.read_text())
    data["characters"].append({"name": "ghost", "mesh": "ghost.obj", "landmarks": "wide.json"})
    data["pairs"] = [{"character": c, "take": "take0"} for c in ("wide", "ghost")]
    changed = manifest_path.parent / "ghost.yaml"
    changed.write_text(yaml.safe_dump(data))
    report = run_batch(plan_batch(read_manifest(changed), tmp_path), workers=0)
    assert report.succeeded == ["wide/take0"]
    assert "character 'ghost'" in report.failed["ghost/take0"] and "does not exist" in report.failed["ghost/take0"]


def test_batch_zip_members_stay_inside(tmp_path):
    import io
    import zipfile

    from retarget.batch.bundle import unpacked_bundle

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        zf.writestr("manifest.json", "{}")
        zf.writestr("../evil.txt", "x")
    (tmp_path / "b.zip").write_bytes(buffer.getvalue())
    with pytest.raises(RetargetError, match="points outside"):
        unpacked_bundle(tmp_path / "b.zip", tmp_path / "out")
    assert not (tmp_path / "out" / ".inputs" / "evil.txt").exists() and not (tmp_path / "evil.txt").exists()


def test_side_files_of_an_obj_and_a_gltf(tmp_path):
    from retarget.batch.plan import side_files

    (tmp_path / "face.obj").write_text("mtllib face.mtl\nusemtl skin\nv 0 0 0\n")
    (tmp_path / "face.mtl").write_text("newmtl skin\nKd 1 1 1\nmap_Kd -s 1 1 1 textures/skin.png\n")
    assert side_files(tmp_path / "face.obj") == [tmp_path / "face.mtl", tmp_path / "skin.png"]
    (tmp_path / "face.gltf").write_text('{"buffers": [{"uri": "face.bin"}], "images": [{"uri": "data:x"}]}')
    assert side_files(tmp_path / "face.gltf") == [tmp_path / "face.bin"]


def test_a_custom_layout_file_reaches_the_workers(manifest_path, reference, client, tmp_path):
    """A character whose layout is a custom layout file (here ibug68's points as the user's
    own layout) and whose landmarks name none: the file is read with the manifest, the
    workers of the cluster register it, and the result is the built-in layout's."""
    data = yaml.safe_load(manifest_path.read_text())
    folder = manifest_path.parent
    assert main(["layouts", "new", "--from", "ibug68", "--description", "my markers",
                 "--out", str(folder / "mine.json")]) == 0
    bare = {"vertex_indices": json.loads((folder / "wide.json").read_text())["vertex_indices"]}
    (folder / "wide_bare.json").write_text(json.dumps(bare))
    data["characters"] = [{**data["characters"][0], "landmarks": "wide_bare.json", "layout": "mine.json"}]
    data["pairs"] = [{"character": "wide", "take": "take0"}]
    changed = folder / "custom.yaml"
    changed.write_text(yaml.safe_dump(data))
    manifest = read_manifest(changed)
    assert manifest.characters[0].layout.startswith("custom-")
    report = run_batch(plan_batch(manifest, tmp_path), client=client)
    assert report.succeeded == ["wide/take0"], report.failed
    mine, built_in = (np.load(root / "wide/take0/vertices.npy") for root in (tmp_path, reference))
    np.testing.assert_allclose(mine, built_in, atol=1e-5)
    data["characters"][0]["layout"] = "nowhere.json"
    changed.write_text(yaml.safe_dump(data))
    with pytest.raises(RetargetError, match="nowhere.json"):
        read_manifest(changed)
