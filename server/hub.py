"""Fan-out of encoded frames to viewers: a one-slot, newest-wins mailbox per viewer.

A slow viewer never slows the source or grows a queue: publishing overwrites whatever
frame the viewer has not taken yet (counted as dropped), and the viewer's sender always
sends the newest frame there is. The hub also owns each project's running source (an
asyncio task), its partial-retargeting regions and its drive (feature points or
muscles or ARKit shapes), so every viewer of a project sees the
same performance; the source stops when the last viewer leaves. Everything runs on the
server's event loop; the hub holds no maths.
"""

from __future__ import annotations

import asyncio
import logging
from collections import defaultdict

__all__ = ["Mailbox", "StreamHub"]

log = logging.getLogger(__name__)


class Mailbox:
    """Holds at most one frame: the newest published and not yet taken.

    delivered, dropped : frames taken by the viewer, and frames overwritten before it
        took them (for the latency and drop figures).
    """

    def __init__(self):
        self._frame: bytes | None = None
        self._ready = asyncio.Event()
        self.delivered = 0
        self.dropped = 0

    def put(self, frame: bytes) -> None:
        if self._frame is not None:
            self.dropped += 1
        self._frame = frame
        self._ready.set()

    async def take(self) -> bytes:
        """Wait for and return the newest frame."""
        await self._ready.wait()
        self._ready.clear()
        frame, self._frame = self._frame, None
        self.delivered += 1
        return frame

    @property
    def backlog(self) -> int:
        """Frames waiting: 0 or 1, never more."""
        return int(self._frame is not None)


class StreamHub:
    """Per project id: the viewers' mailboxes, the running source and its regions.

    A source is any object with ``fps``, ``set_regions(regions)``, ``recording`` (frames
    recorded, None when not recording) and ``async run(hub, project_id)`` that publishes
    encoded frames (`server.players`).
    """

    def __init__(self):
        self._viewers: dict[str, set[Mailbox]] = defaultdict(set)
        self._sources: dict[str, object] = {}
        self._tasks: dict[str, asyncio.Task] = {}
        self._regions: dict[str, list[str] | None] = {}
        self._drives: dict[str, str] = {}
        self._unsaved: dict[str, object] = {}  # a source that ended while recording

    # -- viewers ------------------------------------------------------------------------

    def subscribe(self, project_id: str) -> Mailbox:
        box = Mailbox()
        self._viewers[project_id].add(box)
        return box

    def unsubscribe(self, project_id: str, box: Mailbox) -> None:
        """Forget the viewer's mailbox; the last viewer leaving stops the source."""
        self._viewers[project_id].discard(box)
        if not self._viewers[project_id]:
            del self._viewers[project_id]
            self.stop_source(project_id)
            self._regions.pop(project_id, None)
            self._drives.pop(project_id, None)

    def viewer_count(self, project_id: str) -> int:
        return len(self._viewers.get(project_id, ()))

    def publish(self, project_id: str, frame: bytes) -> None:
        for box in self._viewers.get(project_id, ()):
            box.put(frame)

    # -- sources ------------------------------------------------------------------------

    def source(self, project_id: str):
        """The project's running source, or None."""
        return self._sources.get(project_id)

    def start_source(self, project_id: str, source) -> None:
        """Run `source` for the project (replacing a running one) with its regions."""
        self.stop_source(project_id)
        source.set_regions(self._regions.get(project_id))
        task = asyncio.get_running_loop().create_task(source.run(self, project_id))
        self._sources[project_id], self._tasks[project_id] = source, task
        task.add_done_callback(lambda t: self._finished(project_id, t))

    def stop_source(self, project_id: str) -> bool:
        """Stop the project's source; False when none was running."""
        task = self._tasks.pop(project_id, None)
        self._keep_recording(project_id, self._sources.pop(project_id, None))
        if task is None:
            return False
        task.cancel()
        return True

    def regions(self, project_id: str) -> list[str] | None:
        return self._regions.get(project_id)

    def set_regions(self, project_id: str, regions: list[str] | None) -> None:
        """Partial retargeting for the project's current and later sources (None: all)."""
        source = self._sources.get(project_id)
        if source is not None:
            source.set_regions(regions)  # refuses unknown names before anything changes
        self._regions[project_id] = regions

    def drive(self, project_id: str) -> str:
        """What the project's sources are driven by: "points" (default), "muscles" or "arkit"."""
        return self._drives.get(project_id, "points")

    def set_drive(self, project_id: str, drive: str) -> None:
        """The drive for the project's later sources (the stream sets the running one's)."""
        self._drives[project_id] = drive

    def unsaved_recording(self, project_id: str):
        """The source that stopped or ended while it was recording (once), or None: its
        recording can still be saved."""
        return self._unsaved.pop(project_id, None)

    def _keep_recording(self, project_id: str, source) -> None:
        if getattr(source, "recording", None):
            self._unsaved[project_id] = source

    def _finished(self, project_id: str, task: asyncio.Task) -> None:
        if self._tasks.get(project_id) is task:  # ended by itself, not replaced
            self._tasks.pop(project_id)
            self._keep_recording(project_id, self._sources.pop(project_id, None))
        if not task.cancelled() and task.exception() is not None:
            log.error("stream source of project %s failed", project_id, exc_info=task.exception())
