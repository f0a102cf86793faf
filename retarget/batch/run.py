"""Running a batch's plan: on Dask distributed (a ``LocalCluster`` sized to the machine, a
given number of local workers, or any scheduler), or in this process.

On Dask, each character that has pairs to run is one task (`work.character_state`: mesh,
points, rig, ARKit shapes if asked); its result stays in the memory of the worker that made
it, and the character's pair tasks get its future, so the rig is computed once per
character and moves to another worker at most once (Dask keeps a dependency a worker
fetched), never once per pair. The pair tasks (`work.pair_outputs`) read the take and write
their outputs themselves, so no large array comes back to the client: only a small
`PairResult`. A worker killed mid-task loses that task (and the character states it held),
which the scheduler runs again elsewhere; ``retries`` covers a task that raises anyway.
With a remote scheduler the workers read the inputs and write the outputs at the same
paths as this machine: a shared file system.

The in-process path runs the same functions in the same order and writes the same bytes.
The index is written after every result (at most every `INDEX_INTERVAL` seconds, and at
the end), so an interrupted batch resumes where it stopped.
"""

from __future__ import annotations

import sys
import time
import uuid
from dataclasses import dataclass, field

from tqdm import tqdm

from retarget.batch.plan import Plan, write_index
from retarget.batch.work import PairResult, character_state, pair_outputs, remove_leftovers

__all__ = ["INDEX_INTERVAL", "BatchReport", "run_batch"]

INDEX_INTERVAL = 1.0  # seconds between index writes while results arrive
RETRIES = 2


@dataclass
class BatchReport:
    """What a batch did: keys of the pairs made and skipped, the failed ones with their
    reasons (`failed_before`: those not run again, failed before with the same inputs),
    the wall time in seconds and where it ran."""

    succeeded: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)
    failed_before: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    where: str = ""

    def summary(self) -> str:
        """The lines ``retarget batch`` prints at the end."""
        ran = len(self.succeeded) + len(self.failed)
        rate = f", {ran / self.seconds:.2f} pairs/s" if ran and self.seconds > 0 else ""
        before = f" and {len(self.failed_before)} as before" if self.failed_before else ""
        lines = [f"batch {self.where}: {len(self.succeeded)} succeeded, {len(self.failed)} failed{before}, "
                 f"{len(self.skipped)} skipped (done already) in {self.seconds:.1f} s{rate}"]
        lines += [f"  failed {key}: {reason}" for key, reason in self.failed.items()]
        lines += [f"  failed {key} (as before, inputs unchanged; --retry-failed runs it): {reason}"
                  for key, reason in self.failed_before.items()]
        return "\n".join(lines)


def run_batch(plan: Plan, *, client=None, scheduler: str | None = None, workers: int | None = None,
              quiet: bool = True, on_result=None) -> BatchReport:
    """Run `plan`'s jobs and return the report; the index is updated as results arrive.

    client : a `distributed.Client` to run on (the caller closes it); else
    scheduler : the address of a Dask scheduler (``tcp://HOST:PORT``); else
    workers : 0 runs in this process; N > 0 a ``LocalCluster`` of N single-thread worker
        processes; None a ``LocalCluster`` sized to the machine, or the scheduler named by
        Dask's configuration (``scheduler-address``, ``DASK_SCHEDULER_ADDRESS``) when set.
    quiet : hide the progress bar (pairs done / total, rate, ETA) on stderr.
    on_result : called with each `PairResult` as it arrives (tests, the server).
    """
    start = time.perf_counter()
    report = BatchReport(skipped=list(plan.skipped), failed_before=dict(plan.failed_before))
    bar = tqdm(total=len(plan.jobs), desc="batch", unit="pair", file=sys.stderr, disable=quiet,
               dynamic_ncols=True)
    last_write = [0.0]

    def take(result: PairResult) -> None:
        plan.record(result)
        if result.ok:
            report.succeeded.append(result.key)
        else:
            report.failed[result.key] = result.reason
            bar.set_postfix(failed=len(report.failed))
        bar.update(1)
        if time.perf_counter() - last_write[0] > INDEX_INTERVAL:
            write_index(plan)
            last_write[0] = time.perf_counter()
        if on_result is not None:
            on_result(result)

    try:
        if not plan.jobs:
            report.where = "(nothing to do)"
        elif client is not None:
            report.where = f"on {_describe(client)}"
            _run_dask(plan, client, take)
        elif workers == 0 and scheduler is None:
            report.where = "in one process"
            _run_here(plan, take)
        else:
            with _client(scheduler, workers) as own:
                report.where = f"on {_describe(own)}"
                _run_dask(plan, own, take)
    finally:
        bar.close()
        for job in plan.jobs:  # a worker killed mid-write leaves its temporary file
            remove_leftovers(job.folder)
        write_index(plan)
    report.seconds = time.perf_counter() - start
    return report


def _run_here(plan: Plan, take) -> None:
    """Each character once, then its pairs, in this process (one rig held at a time)."""
    by_character: dict[str, list] = {}
    for job in plan.jobs:
        by_character.setdefault(job.character, []).append(job)
    for name, jobs in by_character.items():
        state = character_state(plan.manifest.character(name), name in plan.arkit)
        for job in jobs:
            take(pair_outputs(state, job))


def _run_dask(plan: Plan, client, take) -> None:
    """Characters as tasks whose futures feed their pairs' tasks; results as they come."""
    from distributed import as_completed

    characters = {}
    for name in dict.fromkeys(job.character for job in plan.jobs):
        # higher priority: a rig is ready before the pairs waiting on it crowd the workers
        characters[name] = client.submit(character_state, plan.manifest.character(name), name in plan.arkit,
                                         pure=False, retries=RETRIES, priority=10,
                                         key=f"character-{name}-{_token()}")
    futures = {client.submit(pair_outputs, characters[job.character], job, pure=False, retries=RETRIES,
                             key=f"pair-{job.key}-{_token()}"): job for job in plan.jobs}
    for future in as_completed(futures):
        job = futures[future]
        try:
            result = future.result()
        except Exception as exc:  # retries spent, or the worker died too often (KilledWorker)
            result = PairResult(job.key, job.digest, False, f"the task failed: {type(exc).__name__}: {exc}")
        take(result)
        future.release()
    for future in characters.values():
        future.release()


class _client:
    """A context manager: a `distributed.Client` of the scheduler, or of a LocalCluster it
    starts (and closes)."""

    def __init__(self, scheduler: str | None, workers: int | None):
        self.scheduler, self.workers = scheduler, workers
        self.cluster = self.client = None

    def __enter__(self):
        import dask
        from distributed import Client, LocalCluster

        address = self.scheduler or (dask.config.get("scheduler-address", None) if self.workers is None else None)
        if address:
            self.client = Client(address)
        else:
            # one thread per worker process: the numpy work holds the GIL for long stretches
            self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                        dashboard_address=None)
            self.client = Client(self.cluster)
        return self.client

    def __exit__(self, *exc):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def _describe(client) -> str:
    info = client.scheduler_info()
    workers = info.get("workers", {})
    threads = sum(w.get("nthreads", 1) for w in workers.values())
    return f"Dask {info.get('address', '')} ({len(workers)} workers, {threads} threads)"


def _token() -> str:
    return uuid.uuid4().hex[:12]
