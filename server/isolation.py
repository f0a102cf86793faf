"""Untrusted files are read in a child process, where a crash cannot take the server down.

Native parsers have no bounds guarantees: a C3D file two bytes away from a valid one made
ezc3d segfault inside the server, killing every viewer's stream and every running job
with it; FFmpeg (through OpenCV) decodes uploaded videos; numpy, zipfile and trimesh can
be made to allocate gigabytes by small files. So every read of uploaded bytes goes
through `Isolation.call`, which runs the reader in a child process forked from a
*forkserver* (a clean single-purpose process that imported the library once, so a child
starts in milliseconds and never inherits the server's threads or sockets) under limits:

- address space: the child's own at start plus `memory_bytes` (RLIMIT_AS), so an
  allocation past the budget is a `MemoryError` in the child, never growth of the server;
- CPU time: `cpu_seconds` (RLIMIT_CPU, then SIGXCPU kills it); wall time: `wall_seconds`,
  after which the parent kills it;
- concurrency: at most `slots` children read at once; a call waits up to `queue_seconds`
  for a slot and is then refused as busy (503). Jobs (tracking a video, computing a rig)
  have slots and limits of their own (`job_slots`, `job_seconds`, `job_memory_bytes`),
  so a long job never holds up an upload.

Rigs are computed here too, though their input is a validated mesh: a dense rig of a
large mesh needs gigabytes, which would otherwise be the server's own growth.

Children are made by `multiprocessing`, so a script that creates the app itself (rather
than `retarget serve`, uvicorn or pytest) must guard its entry point with
``if __name__ == "__main__":``, as multiprocessing requires of every non-fork start.

This module is also the one place where a failure to read untrusted input becomes a
refusal: whatever the child raises or however it dies, the caller gets a `RetargetError`
(HTTP 422) that says what went wrong, or `IsolationBusy` (HTTP 503). A `RetargetError`
raised by the library in the child keeps its own message.
"""

from __future__ import annotations

import multiprocessing
import resource
import signal
import threading
import time
import traceback
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection

from retarget.errors import RetargetError

__all__ = ["Isolation", "IsolationBusy", "IsolationLimits", "PRELOAD"]

PRELOAD = ("ezc3d", "pygltflib", "server.readers", "server.cli")
"""Modules the forkserver imports once, so each child starts with them loaded (the
readers import the library, numpy, trimesh and OpenCV; the glTF reader imports pygltflib
only when it first reads a file, which cost every child reading a glTF ~50 ms of CPU;
`server.cli` is the main module of ``retarget serve``, which multiprocessing re-runs in
every child)."""

_CRASH_SIGNALS = {signal.SIGSEGV, signal.SIGBUS, signal.SIGILL, signal.SIGFPE, signal.SIGABRT}


@dataclass(frozen=True)
class IsolationLimits:
    """What one child may use. memory_bytes: address space beyond what the child holds
    when it starts (the preloaded libraries); cpu_seconds, wall_seconds: CPU and wall
    time of one call; slots: children at once; queue_seconds: how long a call waits for a
    free slot. job_slots, job_seconds, job_memory_bytes: the same for jobs (CPU and wall
    time alike; a job waits for its slot as long as it takes): a dense rig of a
    133k-vertex face peaks at about 0.7 GiB, one of the largest meshes allowed (500k
    vertices) at about 2.7 GiB."""

    memory_bytes: int = 1 << 30
    cpu_seconds: int = 120
    wall_seconds: float = 180.0
    slots: int = 2
    queue_seconds: float = 60.0
    job_slots: int = 2
    job_seconds: int = 3600
    job_memory_bytes: int = 4 << 30


class IsolationBusy(RuntimeError):
    """Every slot stayed busy for `queue_seconds`: the server answers 503."""


_context = multiprocessing.get_context("forkserver")
_context.set_forkserver_preload(list(PRELOAD))


class Isolation:
    """Runs readers of untrusted input in limited child processes (module docstring)."""

    def __init__(self, limits: IsolationLimits = IsolationLimits()):
        self.limits = limits
        self._slots = threading.BoundedSemaphore(limits.slots)
        self._job_slots = threading.BoundedSemaphore(limits.job_slots)

    def warm_up(self) -> None:
        """Start the forkserver now (it imports `PRELOAD`, a second or two) rather than
        on the first upload; safe to call from a background thread."""
        self.call(_nothing, what="warm-up")

    def call(self, fn, /, *args, what: str, progress=None, job: bool = False, **kwargs):
        """``fn(*args, **kwargs)`` run in a child; its return value (pickled back).

        fn : a module-level function (it is pickled by name). With `progress`, fn also
            gets a ``progress`` callable whose calls (any positional arguments) reach
            `progress` here.
        what : how messages name the input, e.g. "not a readable C3D file"; a failure
            is ``RetargetError(f"{what}: {reason}")`` where reason says how the child
            failed (a crash and its signal, memory, time, or the exception).
        job : run under the job limits (`IsolationLimits.job_slots`, ``job_seconds``).

        Raises `RetargetError` for any failure of fn or of the child, `IsolationBusy`
        when no slot frees up in time.
        """
        limits = self.limits
        if job:
            limits = replace(limits, cpu_seconds=limits.job_seconds, wall_seconds=limits.job_seconds,
                             memory_bytes=limits.job_memory_bytes)
        slots = self._job_slots if job else self._slots
        if not slots.acquire(timeout=None if job else limits.queue_seconds):
            raise IsolationBusy(f"the server is busy reading other files ({limits.slots} at "
                                f"once); try again in a minute")
        try:
            return self._run(fn, args, kwargs, what, progress, limits)
        finally:
            slots.release()

    def _run(self, fn, args, kwargs, what, progress, limits: IsolationLimits):
        receive, send = _context.Pipe(duplex=False)
        child = _context.Process(target=_child, daemon=True, name=f"isolated-{fn.__name__}",
                                 args=(send, fn, args, kwargs, progress is not None,
                                       limits.memory_bytes, limits.cpu_seconds))
        child.start()
        send.close()  # the child holds the only writing end: EOF when it dies
        deadline = time.monotonic() + limits.wall_seconds
        try:
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or not receive.poll(remaining):
                    child.kill()
                    raise RetargetError(f"{what}: reading it took more than "
                                        f"{limits.wall_seconds:g} s, the server's limit")
                try:
                    kind, value = receive.recv()
                except (EOFError, OSError):
                    child.join(5)
                    raise RetargetError(f"{what}: {death_reason(child.exitcode, limits)}") from None
                if kind == "progress":
                    progress(*value)
                    continue
                child.join(5)
                if kind == "ok":
                    return value
                if kind == "memory":
                    raise RetargetError(f"{what}: reading it needs more than "
                                        f"{limits.memory_bytes / 2**20:.0f} MiB of memory, "
                                        "the server's limit")
                raise RetargetError(value if kind == "refused" else f"{what}: {value}")
        finally:
            receive.close()
            if child.is_alive():
                child.kill()
                child.join(5)


def death_reason(exitcode: int | None, limits: IsolationLimits) -> str:
    """Why a child that sent no answer ended, in words."""
    if exitcode is not None and exitcode < 0:
        number = -exitcode
        if number == signal.SIGXCPU:
            return f"reading it took more than {limits.cpu_seconds} s of CPU, the server's limit"
        if number == signal.SIGKILL:
            return ("its reader was killed, most likely for using too much memory "
                    f"(the server's limit is {limits.memory_bytes / 2**20:.0f} MiB)")
        name = signal.Signals(number).name if number in signal.Signals._value2member_map_ else number
        if number in _CRASH_SIGNALS:
            return f"the file is malformed: its parser crashed on it ({name})"
        return f"its reader ended on signal {name}"
    return f"its reader ended without an answer (exit status {exitcode})"


def _child(send: Connection, fn, args, kwargs, with_progress: bool, memory_bytes: int,
           cpu_seconds: int) -> None:
    """The child's body: limits, then fn, then one ("ok" | "refused" | "memory" |
    "error", value) message (after any number of ("progress", fraction))."""
    limit_resources(memory_bytes, cpu_seconds)
    if with_progress:
        kwargs = {**kwargs, "progress": lambda *values: send.send(("progress", values))}
    try:
        message = ("ok", fn(*args, **kwargs))
    except RetargetError as exc:
        message = ("refused", str(exc))
    except MemoryError:
        message = ("memory", None)
    except RecursionError:
        message = ("error", "it is nested too deeply to read")
    except Exception as exc:  # noqa: BLE001 - every failure of untrusted input is a refusal
        message = ("error", error_message(exc))
    try:
        send.send(message)
    except MemoryError:
        send.send(("memory", None))


def limit_resources(memory_bytes: int, cpu_seconds: int) -> None:
    """In a child: its address space capped at what it has now plus `memory_bytes`, its
    CPU time at `cpu_seconds` (then SIGXCPU)."""
    _limit(resource.RLIMIT_AS, _address_space() + memory_bytes)
    _limit(resource.RLIMIT_CPU, cpu_seconds)


def error_message(exc: Exception) -> str:
    """An unexpected exception of a child in words: its type, message and where it rose."""
    where = traceback.extract_tb(exc.__traceback__)[-1]
    return (f"{type(exc).__name__}: {str(exc)[:300]} "
            f"(in {where.filename.rsplit('/', 1)[-1]}:{where.lineno})")


def _limit(kind: int, value: int) -> None:
    soft, hard = resource.getrlimit(kind)
    if hard != resource.RLIM_INFINITY:
        value = min(value, hard)
    resource.setrlimit(kind, (value, hard))


def _address_space() -> int:
    """The calling process's virtual memory size, bytes (VmSize)."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[0]) * resource.getpagesize()


def _nothing() -> None:
    return None
