"""`server.isolation`: readers of untrusted input run in limited child processes, and
every way a child can fail becomes a `RetargetError` that says how, while the calling
process carries on."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from retarget.errors import RetargetError
from server.isolation import PRELOAD, Isolation, IsolationBusy, IsolationLimits
from tests.waits import scaled


# -- what the children run (module level: they are pickled by name) ------------------------

def segfault() -> None:
    ctypes.string_at(0)  # reads address 0: SIGSEGV, as a native parser's bad read would


def abort() -> None:
    os.abort()


def allocate(n_bytes: int) -> int:
    return int(np.ones(n_bytes, np.uint8).sum())


def spin() -> None:
    while True:
        pass


def sleep(seconds: float) -> str:
    time.sleep(seconds)
    return "slept"


def refuse() -> None:
    raise RetargetError("not a readable C3D file: the parameter block points past the end")


def index_error() -> None:
    return [][1]


def nested() -> None:
    def deeper(n):
        return deeper(n + 1)
    deeper(0)


def modules() -> set[str]:
    return set(sys.modules)


def counted(n: int, progress) -> np.ndarray:
    for i in range(n):
        progress(i, n)
    return np.arange(n, dtype=np.float32)


def pid() -> int:
    return os.getpid()


@pytest.fixture(scope="module")
def isolation():
    # the wall limit must outlast 2 s of CPU on a loaded machine, or the CPU limit is never seen
    iso = Isolation(IsolationLimits(memory_bytes=256 << 20, cpu_seconds=2, wall_seconds=round(scaled(8))))
    iso.warm_up()
    return iso


def test_a_result_and_progress_come_back_from_another_process(isolation):
    seen = []
    result = isolation.call(counted, 5, what="x", progress=lambda done, total: seen.append((done, total)))
    assert result.tolist() == [0, 1, 2, 3, 4] and result.dtype == np.float32
    assert seen == [(i, 5) for i in range(5)]
    assert isolation.call(pid, what="x") != os.getpid()


@pytest.mark.parametrize("fn, signal", [(segfault, "SIGSEGV"), (abort, "SIGABRT")])
def test_a_crashing_parser_is_a_refusal_naming_the_signal(isolation, fn, signal):
    with pytest.raises(RetargetError) as caught:
        isolation.call(fn, what="not a readable C3D file")
    assert str(caught.value) == (f"not a readable C3D file: the file is malformed: its parser "
                                 f"crashed on it ({signal})")
    assert isolation.call(sleep, 0, what="x") == "slept"  # and the next call works


def test_memory_past_the_budget_is_refused_in_the_child(isolation):
    with pytest.raises(RetargetError, match=r"^big file: reading it needs more than 256 MiB of memory"):
        isolation.call(allocate, 1 << 30, what="big file")
    assert isolation.call(allocate, 64 << 20, what="x") == 64 << 20


def test_cpu_and_wall_time_are_bounded(isolation):
    start = time.monotonic()
    with pytest.raises(RetargetError, match=r"^slow file: reading it took more than 2 s of CPU"):
        isolation.call(spin, what="slow file")
    wall = isolation.limits.wall_seconds
    with pytest.raises(RetargetError, match=rf"^idle file: reading it took more than {wall:g} s"):
        isolation.call(sleep, 60, what="idle file")
    assert time.monotonic() - start < 5 * wall


def test_the_library_s_refusal_keeps_its_message_and_other_errors_are_named(isolation):
    with pytest.raises(RetargetError) as caught:
        isolation.call(refuse, what="ignored")
    assert str(caught.value) == "not a readable C3D file: the parameter block points past the end"
    with pytest.raises(RetargetError, match=r"^odd file: IndexError: list index out of range \(in test_isolation.py:\d+\)$"):
        isolation.call(index_error, what="odd file")
    with pytest.raises(RetargetError, match=r"^deep file: it is nested too deeply to read$"):
        isolation.call(nested, what="deep file")


def test_calls_wait_for_a_free_slot_and_are_refused_as_busy_after_the_queue_time():
    iso = Isolation(IsolationLimits(slots=1, queue_seconds=0.5, wall_seconds=30))
    busy = threading.Thread(target=iso.call, args=(sleep, 3), kwargs={"what": "x"})
    busy.start()
    time.sleep(1.5)  # the first call holds the only slot
    with pytest.raises(IsolationBusy, match="busy reading other files"):
        iso.call(sleep, 0, what="x")
    busy.join()
    assert iso.call(sleep, 0, what="x") == "slept"
    # jobs have slots of their own: a job does not wait behind reads
    assert iso.call(sleep, 0, what="x", job=True) == "slept"


def test_the_serve_command_s_module_imports_no_web_stack_for_the_children_to_repeat():
    # multiprocessing re-runs the main module (`server.cli` under `retarget serve`) in every
    # child; had it imported FastAPI, each upload would pay ~0.3 s of imports in its reader
    loaded = subprocess.run(
        [sys.executable, "-c", "import sys, server.cli; print(' '.join(sorted(sys.modules)))"],
        capture_output=True, text=True, check=True).stdout.split()
    web = sorted({m.split(".")[0] for m in loaded} & {"fastapi", "starlette", "pydantic", "uvicorn", "anyio"})
    assert web == [], f"server.cli imports {web}"
    assert "server.cli" in PRELOAD


def test_a_child_starts_with_the_preloaded_modules():
    # the forkserver skips a preload that fails to import, and each child then pays the import
    assert set(PRELOAD) <= Isolation().call(modules, what="x")
