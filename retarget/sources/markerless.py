"""Markerless face tracking of a video file: MediaPipe's 468-point face mesh, run by the
browser client's own tracker (the web app's ``static/js/tracking/``) in a headless Chromium.

One tracker serves the web app's webcam and this module, which makes it the reference the
native face mesh (`retarget.sources.facemesh_video`: the command line and the server's
video tracking) is checked against (``bench/facemesh.py``); the Python environment needs
no MediaPipe wheel (the PyPI one pins numpy < 2 and brings a second OpenCV).

How a video is tracked
----------------------
Python decodes the video (`retarget.sources.video.VideoReader`, OpenCV) and hands the
page one frame at a time as a JPEG (quality 95); the page (the web app's ``static/track.html``)
tracks it while it fetches the next one, and posts back the layout's points about once a
second (``track.html`` describes the exchange). Nothing
listens on a port: the page, its modules, the face-mesh package and the frames are all
answered through Playwright's request interception (``page.route``) on a made-up origin,
from the web app's folder, which the caller names (`web_root`: the library does not know
where the web app is installed; the server's ``retarget`` command gives its own).

Decoding here rather than in the page, for robustness first: OpenCV reads any codec its
FFmpeg reads (Chromium plays neither OpenCV's own mp4v MP4 nor MJPG AVI, and a build
without proprietary codecs no H.264), gives the frame count and rate from the container
(a <video> states neither), and `VideoReader` names the file and the problem when it is
broken. And for speed: a <video> has no frame-exact stepping (a seek decodes from the previous key
frame: 54 ms a frame over the first 150 frames of a 480 x 480 H.264 file with a key frame
every 250 frames; pausing playback on each frame waits about a frame period, 28 ms at
30 fps), while OpenCV decodes a frame in under 1 ms and the JPEG hand-over costs about
10 ms (``bench/markerless.py``).

Points are in pixels, **x right, y up, z toward the camera**, origin at the image's
bottom-left corner, z in the same pixel scale as x (MediaPipe's normalised landmarks times
the frame width; y flipped), so a take from here and one from the marker trackers share
their x, y conventions.
"""

from __future__ import annotations

import mimetypes
import re
import time
from pathlib import Path

import cv2
import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import Layout, get_layout
from retarget.sources.facemesh_video import check_max_frames, face_mesh_take
from retarget.sources.take import Take

__all__ = ["track_video_markerless", "TRACKER"]

TRACKER = "@mediapipe/face_mesh 0.4.1633559619"
"""The face tracker the page runs (the web app's package.json pins it)."""

_ORIGIN = "http://retarget.localhost"  # never resolved: every request is intercepted
_CHROMIUM_ARGS = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]
_JPEG_QUALITY = 95
_PAGE_TIMEOUT_MS = 120_000  # browser start and model load on a busy machine
_FRAME = re.compile(r"/frames/(\d+)")
_POINTS = re.compile(r"/points/(\d+)")
_DONE = re.compile(r"done=(\d+)")
_TYPES = {".js": "text/javascript", ".html": "text/html", ".wasm": "application/wasm"}


def track_video_markerless(
    path,
    *,
    layout: str | Layout,
    web_root,
    progress=None,
    max_frames: int | None = None,
    chromium: str | None = "/usr/bin/chromium",
) -> Take:
    """Track the face in a video file with the browser's face-mesh tracker.

    path : a video file OpenCV can decode.
    layout : a layout name (`retarget.layouts.LAYOUTS`) or a `Layout`; its `mediapipe468`
        indices pick its points out of the 468 landmarks.
    web_root : the web app's folder (a path): its ``static/`` pages and modules and its
        ``node_modules/@mediapipe/face_mesh`` package (``npm ci``) are what the page runs.
    progress : optional ``progress(done, total)`` called after each tracked frame; total is
        the expected frame count (`max_frames` or the header's), None when unknown.
    max_frames : track at most this many frames from the start.
    chromium : the Chromium executable, or None for Playwright's own build
        (``playwright install chromium``).

    Returns a `Take`: points (F, N, 3) float32, pixels (x right, y up, z toward the
    camera; see the module docstring), a frame without a face all NaN; source
    "markerless"; meta: width, height, units, tracker, frames_with_face, face_share
    (their share of the frames), fps_tracked (frames per second of decoding, hand-over
    and tracking, browser start and model load excluded: those are startup_s), truncated
    (fewer decodable frames than the header said), fps_from_header (False: the container
    gave no rate and `fps` is `retarget.sources.take.DEFAULT_FPS`). A video in which no face is ever
    found is returned all NaN with face_share 0, and a `RuntimeWarning` says so.

    Raises `RetargetError` for a missing or undecodable video, a bad `max_frames`, a
    missing Playwright, Chromium or npm package, or a tracker failure (the page's error).
    Uses Playwright's sync API: call it from a thread without a running asyncio loop.
    """
    lay = layout if isinstance(layout, Layout) else get_layout(layout)
    check_max_frames(max_frames)
    web = Path(web_root)
    _check_web_files(web)
    sync_playwright, playwright_error = _playwright()
    if chromium is not None and not Path(chromium).is_file():
        raise RetargetError(
            f"Chromium not found at {chromium!r}: install it (Debian/Ubuntu: apt-get install "
            f"chromium), pass chromium=<its path>, or chromium=None for Playwright's own "
            f"(playwright install chromium)")

    from retarget.sources.video import VideoReader

    with VideoReader(path) as reader:
        width, height = reader.size
        fps = float(reader.fps)
        fps_known = bool(reader.fps_known)
        expected = reader.n_frames or None
        if max_frames is not None:
            expected = min(expected, int(max_frames)) if expected else int(max_frames)
        feed = _FrameFeed(reader, web, lay.n_points, int(max_frames) if max_frames else None,
                          expected, progress)
        start = time.perf_counter()
        with sync_playwright() as p:
            try:
                browser = p.chromium.launch(executable_path=chromium, args=_CHROMIUM_ARGS)
            except playwright_error as exc:
                raise RetargetError(f"could not start Chromium ({chromium or 'Playwright build'}): "
                                    f"{_first_line(exc)}") from None
            try:
                page = browser.new_page()
                page.set_default_timeout(_PAGE_TIMEOUT_MS)
                page.route(f"{_ORIGIN}/**", feed.answer)
                page.route(re.compile(r"^(?!" + re.escape(_ORIGIN) + r"/).*"),
                           lambda route: route.abort())  # nothing leaves the machine
                page.goto(f"{_ORIGIN}/static/track.html")
                page.wait_for_function("() => window.retargetTracking")
                page.evaluate("() => window.retargetTracking.tracker.init().then(() => null)")
                startup = time.perf_counter() - start
                tracking = time.perf_counter()
                count = page.evaluate("(indices) => window.retargetTracking.trackServedFrames(indices)",
                                      list(lay.mediapipe468))
                seconds = time.perf_counter() - tracking
            except playwright_error as exc:
                feed.raise_failure()
                raise RetargetError(f"markerless tracking of {str(path)!r} failed in the browser: "
                                    f"{_first_line(exc)}") from None
            finally:
                browser.close()
        feed.raise_failure()
        truncated = bool(getattr(reader, "truncated", False))

    return face_mesh_take(path, feed.points[:count], lay, size=(width, height), fps=fps, fps_known=fps_known,
                          tracker=TRACKER, seconds=seconds, startup=startup, truncated=truncated)


class _FrameFeed:
    """The page's requests answered from this process: the tracker's files, the video's
    frames in order, and the points the page posts back.

    Playwright calls `answer` on this thread while `page.evaluate` waits, so an exception
    here (a failing `progress`, Ctrl-C) would only stall the page: it is kept, the page gets
    a 500 for this and every later request, which ends its loop, and `raise_failure`
    raises it once the evaluate returns."""

    def __init__(self, reader, web: Path, n_points: int, max_frames: int | None,
                 expected: int | None, progress) -> None:
        self.frames = iter(reader)
        self.web = web
        self.next_index = 0
        self.max_frames = max_frames
        self.expected = expected
        self.progress = progress
        self.n_points = n_points
        self.points = np.full((min(expected or 256, 4096), n_points, 3), np.nan, dtype=np.float32)
        self.done = 0
        self.failure: BaseException | None = None

    def answer(self, route) -> None:
        if self.failure is not None:  # stop the page at its next request
            route.fulfill(status=500, body=f"stopped: {type(self.failure).__name__}")
            return
        try:
            self._answer(route)
        except BaseException as exc:  # noqa: BLE001 - kept and re-raised by raise_failure
            if self.failure is None:
                self.failure = exc
            route.fulfill(status=500, body=f"{type(exc).__name__}: {exc}")

    def raise_failure(self) -> None:
        if self.failure is not None:
            raise self.failure

    def _answer(self, route) -> None:
        request = route.request
        path, _, query = request.url[len(_ORIGIN):].partition("?")
        if (m := _FRAME.fullmatch(path)) and request.method == "GET":
            reply = self._frame(int(m.group(1)))
            if done := _DONE.fullmatch(query):
                self._report(int(done.group(1)))  # before fulfilling: a failure gets the 500
            route.fulfill(**reply)
        elif (m := _POINTS.fullmatch(path)) and request.method == "POST":
            self._report(self._store(int(m.group(1)), request.post_data_buffer or b""))
            route.fulfill(status=204)
        elif (file := _static_file(self.web, path)) is not None:
            kind = _TYPES.get(file.suffix) or mimetypes.guess_type(file.name)[0] or "application/octet-stream"
            route.fulfill(body=file.read_bytes(), content_type=kind)
        else:
            route.fulfill(status=404, body=f"not found: {path}")

    def _frame(self, index: int) -> dict:
        if index != self.next_index:
            raise RetargetError(f"the page asked for frame {index}, frame {self.next_index} is next")
        if self.max_frames is not None and index >= self.max_frames:
            return {"status": 204}
        item = next(self.frames, None)
        if item is None:
            return {"status": 204}
        _, bgr = item
        self.next_index += 1
        ok, jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, _JPEG_QUALITY])
        if not ok:
            raise RetargetError(f"frame {index} could not be encoded for the page")
        return {"body": jpeg.tobytes(), "content_type": "image/jpeg"}

    def _store(self, first: int, body: bytes) -> int:
        """Keep the points of frames first, first + 1, ...; the frame after the last."""
        values = np.frombuffer(body, dtype="<f4")
        if values.size == 0 or values.size % (self.n_points * 3):
            raise RetargetError(f"the page sent {values.size} values from frame {first}, "
                                f"not a positive multiple of {self.n_points} points x 3")
        frames = values.reshape(-1, self.n_points, 3)
        stop = first + len(frames)
        if stop > len(self.points):
            grown = np.full((max(2 * len(self.points), stop), self.n_points, 3), np.nan, np.float32)
            grown[:len(self.points)] = self.points
            self.points = grown
        self.points[first:stop] = frames
        return stop

    def _report(self, done: int) -> None:
        if done > self.done:
            self.done = done
            if self.progress is not None:
                self.progress(done, self.expected)


def _static_file(web: Path, path: str) -> Path | None:
    """The file behind a page URL path, only inside the folders of the web app `web` that
    the page may read."""
    for prefix, folder in (("/static/", web / "static"),
                           ("/vendor/@mediapipe/face_mesh/", web / "node_modules" / "@mediapipe" / "face_mesh")):
        if path.startswith(prefix):
            file = (folder / path[len(prefix):]).resolve()
            if file.is_relative_to(folder.resolve()) and file.is_file():
                return file
    return None


def _check_web_files(web: Path) -> None:
    page = web / "static" / "track.html"
    package = web / "node_modules" / "@mediapipe" / "face_mesh" / "face_mesh.js"
    if not page.is_file():
        raise RetargetError(f"markerless tracking needs the browser client's files; {page} is missing")
    if not package.is_file():
        raise RetargetError(f"markerless tracking needs the npm package @mediapipe/face_mesh; "
                            f"{package} is missing: run npm ci --prefix {web}")


def _playwright():
    try:
        from playwright.sync_api import Error, sync_playwright
    except ImportError:
        raise RetargetError(
            "markerless tracking runs the face tracker in a headless Chromium through "
            "Playwright, which is not installed: pip install 'retarget[markerless]', then "
            "apt-get install chromium (or playwright install chromium)") from None
    return sync_playwright, Error


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__
