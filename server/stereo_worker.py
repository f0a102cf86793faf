"""A live stereo session's decoding and tracking, in a long-lived child process of its own.

A live stereo source sends two JPEGs a frame from the network, and JPEG decoding is a
native parser: a hostile file that crashed it inside the server would end every stream
and job. So, as `server.isolation` does for uploads, each session gets one child process
(forked from the same forkserver, under an address-space and a CPU-time limit) that
decodes its frames and runs the library's `retarget.sources.stereo_live` objects: the
calibration being built, then the tracker. The child lives as long as the session, since
the tracker's state (its templates, head frame and temporal mean) is the point of it.

The parent talks to it by request and answer over a pipe (`StereoWorker.call`, blocking:
the router runs it in a thread). A library refusal (`RetargetError`, e.g. a JPEG of the
wrong size) comes back as a `RetargetError` and the session goes on; a child that dies
(a crash, a limit) or does not answer in time raises `WorkerDied`, which says why, and
the session ends.
"""

from __future__ import annotations

import multiprocessing

import cv2

from retarget.errors import RetargetError
from retarget.sources.calibration import StereoCalibration
from retarget.sources.jpeg_frames import decoded_jpeg
from retarget.sources.stereo_live import LiveCalibration, LiveStereoTracker
from retarget.sources.stereo_live_stickers import LiveStickerTracker, by_name
from server.isolation import IsolationLimits, death_reason, error_message, limit_resources

__all__ = ["StereoWorker", "WorkerDied"]

_context = multiprocessing.get_context("forkserver")  # the one `server.isolation` preloads


class WorkerDied(RuntimeError):
    """The session's child ended or stopped answering; the message says why."""


class StereoWorker:
    """One live stereo session's child process (module docstring).

    memory_bytes : address space the child may add to what it holds at start;
    cpu_seconds : CPU time over the whole session (RLIMIT_CPU);
    call_seconds : how long one request may take before the child is killed.
    """

    def __init__(self, *, memory_bytes: int = 512 << 20, cpu_seconds: int = 3600,
                 call_seconds: float = 20.0, name: str = "stereo-live"):
        self.memory_bytes, self.cpu_seconds, self.call_seconds = memory_bytes, cpu_seconds, call_seconds
        self._conn, child_conn = _context.Pipe(duplex=True)
        self.process = _context.Process(target=_serve, name=name, daemon=True,
                                        args=(child_conn, memory_bytes, cpu_seconds))
        self.process.start()
        child_conn.close()  # the child holds the only other end: EOF when it dies

    def call(self, kind: str, *args, seconds: float | None = None):
        """The child's answer to request `kind` (see `_REQUESTS`); `RetargetError` for a
        refusal, `WorkerDied` when the child dies or takes longer than `seconds`
        (default `call_seconds`)."""
        try:
            self._conn.send((kind, args))
            if not self._conn.poll(seconds or self.call_seconds):
                self.close()
                raise WorkerDied(f"the stereo tracker took more than {seconds or self.call_seconds:g} s "
                                 "on one request, the server's limit")
            status, value = self._conn.recv()
        except (EOFError, OSError, BrokenPipeError):
            self.process.join(5)
            limits = IsolationLimits(memory_bytes=self.memory_bytes, cpu_seconds=self.cpu_seconds)
            raise WorkerDied(f"the stereo tracker stopped: {death_reason(self.process.exitcode, limits)}") from None
        if status == "refused":
            raise RetargetError(value)
        if status == "error":
            raise WorkerDied(f"the stereo tracker failed: {value}")
        return value

    def close(self) -> None:
        """End the child (idempotent)."""
        self._conn.close()
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)


def _calibrate(state: dict, pattern, size) -> dict:
    state["calibration"] = LiveCalibration(pattern, size)
    state["size"] = tuple(size)
    return {"count": 0, "needed": state["calibration"].min_views}


def _view(state: dict, left: bytes, right: bytes) -> dict:
    live = state.get("calibration")
    if live is None:
        raise RetargetError('send {"type": "calibrate", ...} before the calibration views')
    good = live.add_views(decoded_jpeg(left, live.size, "left image"),
                          decoded_jpeg(right, live.size, "right image"))
    return {"good": good, "count": live.count, "needed": live.min_views}


def _solve(state: dict) -> dict:
    live = state.get("calibration")
    if live is None:
        raise RetargetError("no calibration under way")
    return live.calibrate().to_dict()


def _track(state: dict, calibration: dict, layout, stickers: dict | None = None) -> dict:
    calibration = StereoCalibration.from_dict(calibration)
    if stickers is None:
        state["tracker"], state["names"] = LiveStereoTracker(calibration, layout), None
    else:
        state["tracker"] = LiveStickerTracker(calibration, stickers["color"], anchors=stickers.get("anchors"),
                                              layout=layout)
        state["names"] = layout.point_names   # the columns go to these by their names_
    return {"size": list(calibration.size)}


def _pair(state: dict, left: bytes, right: bytes, time: float):
    tracker = state.get("tracker")
    if tracker is None:
        raise RetargetError('send {"type": "start"} before the frames to track')
    size = tracker.calibration.size
    points = tracker.push(decoded_jpeg(left, size, "left image"), decoded_jpeg(right, size, "right image"), time)
    stickers = state["names"] is not None
    info = {"identified": tracker.identified_, "anchored": tracker.anchored_,
            "detail": "" if (tracker.anchored_ if stickers else tracker.identified_) else tracker.setup_error_}
    if stickers:
        anchors = tracker.anchors_
        info.update(stickers=len(tracker.names_),
                    anchors=[] if anchors is None else [f"m{a + 1:02d}" for a in anchors.tolist()])
        points = by_name(points, tracker.names_, state["names"])
    return points, info


_REQUESTS = {"calibrate": _calibrate, "view": _view, "solve": _solve, "track": _track, "pair": _pair}
"""What the child answers: calibrate(pattern, size) starts a calibration; view(left, right)
adds a pair of JPEGs to it; solve() returns the calibration's dict; track(calibration
dict, layout, stickers=None) starts a tracker of the layout's colour markers, or with
stickers ``{"color", "anchors"}`` a `LiveStickerTracker` whose columns go to the layout's
points by place (a layout made from a stereo sticker take) or else m01..mM by name; pair(left, right, time) tracks a pair of JPEGs, returning
((N, 3) float32 points in the layout's order, info)."""


def _serve(conn, memory_bytes: int, cpu_seconds: int) -> None:
    """The child's body: limits, then one answer per request until the pipe closes."""
    limit_resources(memory_bytes, cpu_seconds)
    cv2.setNumThreads(1)  # one session, one core: the server's other work keeps the rest
    state: dict = {}
    while True:
        try:
            kind, args = conn.recv()
        except (EOFError, OSError):
            return
        try:
            answer = ("ok", _REQUESTS[kind](state, *args))
        except RetargetError as exc:
            answer = ("refused", str(exc))
        except MemoryError:
            answer = ("error", f"it needed more than {memory_bytes / 2**20:.0f} MiB of memory, the server's limit")
        except Exception as exc:  # noqa: BLE001 - the parent ends the session with the reason
            answer = ("error", error_message(exc))
        conn.send(answer)
