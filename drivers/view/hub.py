"""Fan-out of the session's messages to the connected pages, with bounded queues (drop the oldest, count).

The session thread calls `publish_threadsafe`; messages land in a bounded inbox (`INBOX` deep) that the
event loop drains into every client's queue (`CLIENT_QUEUE` deep). A page that reads slower than the
device produces loses its oldest images and ticks first (state changes and calibrations go last), counted
in `Client.dropped` and `Hub.dropped`; memory never grows with a slow browser. Sticky messages (the last
of each kind in `STICKY`) are replayed to a page that connects later, so it starts with the device's
description, state and last calibration.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections import deque

INBOX = 512
CLIENT_QUEUE = 64
STICKY = ("hello", "state", "calibration", "script")

Message = dict | bytes


def _sticky(message: Message) -> bool:
    return isinstance(message, dict) and message.get("type") in STICKY


class Client:
    """One page: its queue of messages to send and how many it lost."""

    def __init__(self, maxsize: int = CLIENT_QUEUE) -> None:
        self.queue: deque[Message] = deque()
        self.maxsize = maxsize
        self.ready = asyncio.Event()
        self.dropped = 0

    def put(self, message: Message) -> bool:
        """Queue `message`; if full, drop the oldest image or tick (else the oldest message) and return False."""
        full = len(self.queue) >= self.maxsize
        if full:
            victim = next((i for i, m in enumerate(self.queue) if not _sticky(m)), 0)
            del self.queue[victim]
            self.dropped += 1
        self.queue.append(message)
        self.ready.set()
        return not full

    async def get_all(self) -> list[Message]:
        """Wait for messages; take every queued one."""
        await self.ready.wait()
        self.ready.clear()
        out = list(self.queue)
        self.queue.clear()
        return out


class Hub:
    """See the module docstring. Create it on the event loop's thread."""

    def __init__(self, loop: asyncio.AbstractEventLoop, client_queue: int = CLIENT_QUEUE) -> None:
        self.loop, self.client_queue = loop, client_queue
        self.clients: set[Client] = set()
        self.sticky: dict[str, Message] = {}
        self.dropped = 0  # messages lost in the inbox or in a client's queue
        self._inbox: deque[Message] = deque()
        self._lock = threading.Lock()
        self._scheduled = False

    def attach(self) -> Client:
        """A new page: a client primed with the sticky messages."""
        client = Client(self.client_queue)
        for message in self.sticky.values():
            client.put(message)
        self.clients.add(client)
        return client

    def detach(self, client: Client) -> None:
        self.clients.discard(client)

    def publish(self, message: Message) -> None:
        """On the loop: queue `message` for every page."""
        if isinstance(message, dict) and message.get("type") in STICKY:
            self.sticky[message["type"]] = message
        if isinstance(message, dict) and message.get("type") == "tick":
            message["stats"]["view_dropped"] = self.dropped
        for client in self.clients:
            if not client.put(message):
                self.dropped += 1

    def publish_threadsafe(self, message: Message) -> None:
        """From any thread: queue `message` in the bounded inbox and have the loop deliver it."""
        with self._lock:
            if len(self._inbox) >= INBOX:
                self._inbox.popleft()
                self.dropped += 1
            self._inbox.append(message)
            if self._scheduled:
                return
            self._scheduled = True
        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody to deliver to
            self.loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        with self._lock:
            messages = list(self._inbox)
            self._inbox.clear()
            self._scheduled = False
        for message in messages:
            self.publish(message)
