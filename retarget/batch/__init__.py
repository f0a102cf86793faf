"""Batch retargeting: many characters x many takes, on one machine or a Dask cluster.

A manifest (YAML or JSON, `manifest.read_manifest`) lists characters (a mesh, its
landmarks and rig settings, or a project exported from the app) and takes (any file the
app imports, with their conditioning settings), and what to make of each pair (a glTF
with the take, ARKit weights as Live Link Face CSV, the vertices as ``.npy``).
`plan.plan_batch` hashes every pair's inputs and settings and, against the index
``.retarget-batch.json`` in the output folder, says which pairs are done already;
`run.run_batch` runs the others (`work` holds what one task does: a character's rig,
once per character, and a pair's outputs, written atomically), on a Dask
``LocalCluster``, a given scheduler, or in this process.

    manifest.py   the manifest file -> typed, checked entries
    plan.py       pairs, their content hashes, the index, what to skip
    work.py       one character's state (mesh, points, rig, shapes); one pair's outputs
    run.py        Dask or in-process execution, progress, the report
"""

from retarget.batch.manifest import Manifest, read_manifest
from retarget.batch.plan import INDEX_NAME, Plan, plan_batch
from retarget.batch.run import BatchReport, run_batch

__all__ = ["INDEX_NAME", "BatchReport", "Manifest", "Plan", "plan_batch", "read_manifest", "run_batch"]
