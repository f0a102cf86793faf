"""Fan-out of encoded frames to viewers: a one-slot, newest-wins mailbox per viewer.

A slow viewer never slows the source or grows a queue: publishing overwrites whatever
frame the viewer has not taken yet (counted as dropped), and the viewer's sender always
sends the newest frame there is. Everything runs on the server's event loop.
"""

from __future__ import annotations

import asyncio
from collections import defaultdict


class Mailbox:
    """Holds at most one frame: the newest published and not yet taken."""

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
        return int(self._frame is not None)


class StreamHub:
    """Viewers' mailboxes per project id."""

    def __init__(self):
        self._viewers: dict[str, set[Mailbox]] = defaultdict(set)

    def subscribe(self, project_id: str) -> Mailbox:
        box = Mailbox()
        self._viewers[project_id].add(box)
        return box

    def unsubscribe(self, project_id: str, box: Mailbox) -> None:
        self._viewers[project_id].discard(box)
        if not self._viewers[project_id]:
            del self._viewers[project_id]

    def viewer_count(self, project_id: str) -> int:
        return len(self._viewers.get(project_id, ()))

    def publish(self, project_id: str, frame: bytes) -> None:
        for box in self._viewers.get(project_id, ()):
            box.put(frame)
