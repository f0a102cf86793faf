"""Test helpers that check a glTF file with tools other than ours (no retarget imports).

`validation_report` runs the Khronos glTF Validator (npm ``gltf-validator``, installed in
web/node_modules by ``npm ci --prefix web``) through node on a file; `assert_valid_gltf`
fails a test on any error or warning it reports (infos and hints, such as an unused
TEXCOORD_0 without a material, are allowed).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VALIDATE = ROOT / "tests" / "js" / "validate_gltf.mjs"


def validation_report(path) -> dict:
    """The validator's report on the file at `path` (its JSON object)."""
    node = shutil.which("node")
    assert node, "node is needed to run the Khronos glTF Validator"
    assert (ROOT / "web" / "node_modules" / "gltf-validator").is_dir(), \
        "gltf-validator is missing: run `npm ci --prefix web`"
    run = subprocess.run([node, str(VALIDATE), str(path)], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, f"the validator failed: {run.stderr[-2000:]}"
    return json.loads(run.stdout)


def assert_valid_gltf(path) -> dict:
    """Fail unless the validator reports no error and no warning; returns the report."""
    report = validation_report(path)
    issues = report["issues"]
    serious = [m for m in issues["messages"] if m["severity"] <= 1]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, \
        f"{issues['numErrors']} errors, {issues['numWarnings']} warnings: {serious[:10]}"
    return report
