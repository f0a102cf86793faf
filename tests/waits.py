"""Waiting in tests: one timeout scale for loaded machines and one way to wait for a
server job (TestClient or a real server alike)."""

from __future__ import annotations

import os
import time

_MAX_SCALE = 4.0


def timeout_scale() -> float:
    """How many times longer than on a quiet machine a wait may last.

    ``RETARGET_TEST_TIMEOUT_SCALE`` when set; else the machine's load per core over the
    last minute (at least 1, at most 4), read when the wait starts: a timeout is there to
    end a hang, not to time the code, and a CI runner shared with other jobs is slower
    without anything being wrong.
    """
    asked = os.environ.get("RETARGET_TEST_TIMEOUT_SCALE")
    if asked:
        return float(asked)
    load = os.getloadavg()[0] / (os.cpu_count() or 1)
    return min(max(1.0, load), _MAX_SCALE)


def scaled(seconds: float) -> float:
    """`seconds` (a timeout that holds on a quiet machine) times `timeout_scale()`."""
    return seconds * timeout_scale()


def scaled_ms(milliseconds: float) -> float:
    """`scaled` for Playwright's timeouts, which are in milliseconds."""
    return milliseconds * timeout_scale()


def _get_json(api, path: str) -> dict:
    """GET `path` as JSON from a TestClient or an e2e `Server`."""
    if hasattr(api, "api"):
        return api.api("GET", path)
    reply = api.get(path)
    assert reply.status_code == 200, reply.text
    return reply.json()


def wait_job(api, job_id: str, timeout_s: float = 60.0, *, poll_s: float = 0.02,
             progress: list | None = None) -> dict:
    """The job's JSON once it has stopped running (done or failed: the caller asserts
    which). `api` is a TestClient or an e2e `Server`; `progress`, when given, collects the
    progress figure of every poll. Fails after ``scaled(timeout_s)``."""
    deadline = time.monotonic() + scaled(timeout_s)
    while True:
        job = _get_json(api, f"/api/jobs/{job_id}")
        if progress is not None:
            progress.append(job["progress"])
        if job["state"] != "running":
            return job
        assert time.monotonic() < deadline, f"job still running after {scaled(timeout_s):.0f} s: {job}"
        time.sleep(poll_s)
