"""Background jobs: one thread per job, at most one running job per project, except jobs
started as not exclusive (finding landmarks), which run beside the others and only one at
a time of their kind.

Jobs live in memory only (a restart forgets them; what a finished job produced is in the
store). A job's `progress` is fed by the library's ``progress(fraction)`` callback; a
finished job has a `detail` sentence for people and a `result` object for programs (a
failed one: the reason in `detail`, no result).
"""

from __future__ import annotations

import secrets
import threading
from dataclasses import dataclass, field

from retarget.errors import RetargetError

__all__ = ["Job", "JobBusy", "JobRegistry"]


class JobBusy(RuntimeError):
    """The project already has a running job; the message names it."""


@dataclass
class Job:
    """One background task. `state` is "running", "done" or "failed"; `progress` in [0, 1];
    `detail` says what failed (or what was made); `result` is what a done job made, as
    JSON (e.g. ``{"take": id, "frames": n}``), else None."""

    id: str
    project_id: str
    kind: str
    state: str = "running"
    progress: float = 0.0
    detail: str = ""
    result: dict | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _thread: threading.Thread | None = field(default=None, repr=False)
    _slot: str = field(default="", repr=False)  # its key among the registry's running jobs

    def report(self, fraction: float) -> None:
        """The library's progress callback: keeps the largest fraction seen, in [0, 1]."""
        with self._lock:
            self.progress = max(self.progress, min(max(float(fraction), 0.0), 1.0))

    def as_json(self) -> dict:
        with self._lock:
            return {"id": self.id, "project_id": self.project_id, "kind": self.kind,
                    "state": self.state, "progress": self.progress, "detail": self.detail,
                    "result": self.result}


class JobRegistry:
    """Starts jobs in daemon threads and keeps their state for polling."""

    def __init__(self):
        self._jobs: dict[str, Job] = {}
        self._running: dict[str, str] = {}  # project id (or "id/kind") -> running job id
        self._lock = threading.Lock()

    def start(self, project_id: str, kind: str, work, *, exclusive: bool = True) -> Job:
        """Run ``work(job)`` in a thread; on success it returns (detail sentence, result
        object).

        A `RetargetError` (or `ValueError`) fails the job with its message; any other
        exception fails it as an internal error. Raises `JobBusy` when the project has a
        running job (with `exclusive` False: a running job of the same kind). A job that
        is not exclusive must check what it stores against the project's revision, as
        finding landmarks does: a rig may be computed while it runs, and the other way round.
        """
        slot = project_id if exclusive else f"{project_id}/{kind}"
        with self._lock:
            if slot in self._running:
                raise JobBusy(
                    f"project {project_id!r} already has a running {'' if exclusive else kind + ' '}"
                    f"job {self._running[slot]!r}; wait for it to finish"
                )
            job = Job(secrets.token_urlsafe(12), project_id, kind)
            job._slot = slot
            self._jobs[job.id] = job
            self._running[slot] = job.id
        job._thread = threading.Thread(target=self._run, args=(job, work), daemon=True,
                                       name=f"job-{kind}-{job.id}")
        job._thread.start()
        return job

    def _run(self, job: Job, work) -> None:
        result = None
        try:
            detail, result = work(job)
            state = "done"
        except (RetargetError, ValueError, LookupError, RuntimeError) as exc:
            state, detail = "failed", str(exc)
        except Exception as exc:  # noqa: BLE001 - a job must always end in a state
            state, detail = "failed", f"internal error: {type(exc).__name__}: {exc}"
        with job._lock:
            job.state, job.detail, job.result = state, detail or "", result
            if state == "done":
                job.progress = 1.0
        with self._lock:
            self._running.pop(job._slot, None)

    def running(self, project_id: str, kind: str) -> Job | None:
        """The project's running job of `kind`, or None (a page that reloads finds the
        job it started)."""
        with self._lock:
            job_id = self._running.get(project_id) or self._running.get(f"{project_id}/{kind}")
            job = self._jobs.get(job_id) if job_id else None
        return job if job is not None and job.kind == kind else None

    def get(self, job_id: str) -> Job | None:
        with self._lock:
            return self._jobs.get(job_id)

    def wait(self, job_id: str, timeout: float | None = None) -> None:
        """Block until the job's thread ends (for tests and shutdown)."""
        job = self.get(job_id)
        if job is not None and job._thread is not None:
            job._thread.join(timeout)
