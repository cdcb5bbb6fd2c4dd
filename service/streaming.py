"""Per-socket event queues: bounded, and a slow client gets the newest solution.

Each WebSocket gets an :class:`EventQueue` fed by a producer task that reads the backend's event
iterator (the backend keeps one reader per job per API process and fans out through its
:class:`~workers.backend.EventHub`, so a slow socket never holds up another). The sender drains the
queue to the socket.

Coalescing: while the queue has room every event is kept. When it is full, queued ``solution``
events older than the newest solution are dropped (the incoming event when it is a solution, else
the newest queued one); ``queued``, ``started``, ``progress`` and terminal events are never dropped.
If nothing can be dropped the producer waits for room (backpressure), which is safe because the
hub keeps the job's whole log. A client therefore sees every non-solution event in order, the
newest solution as soon as it can take it, and always the terminal event.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import AsyncIterator

from schemas import EventType, JobEvent


class EventQueue:
    """A bounded FIFO of job events with newest-solution coalescing (see the module docstring).

    Parameters
    ----------
    maxsize:
        Events held before coalescing starts (``SEGUE_WS_QUEUE``), at least 2.

    Examples
    --------
    >>> from schemas import JobEvent
    >>> q = EventQueue(2)
    >>> ev = lambda i, t: JobEvent(id=i, job="j", type=t, time=0.0)
    >>> [q.offer(ev(i, "solution")) for i in (1, 2, 3)]
    [True, True, True]
    >>> [e.id for e in q.drain()], q.dropped
    ([3], 2)
    """

    def __init__(self, maxsize: int) -> None:
        if maxsize < 2:
            raise ValueError(f"an event queue needs room for at least 2 events, not {maxsize}")
        self.maxsize = maxsize
        self.dropped = 0
        self._items: deque[JobEvent] = deque()
        self._closed = False
        self._readable = asyncio.Event()
        self._writable = asyncio.Event()

    def __len__(self) -> int:
        return len(self._items)

    @property
    def closed(self) -> bool:
        """True once the producer is done (remaining events can still be read)."""
        return self._closed

    def offer(self, event: JobEvent) -> bool:
        """Add an event without waiting; False when the queue is full and nothing can be dropped."""
        if self._closed:
            raise RuntimeError("the event queue is closed")
        if len(self._items) >= self.maxsize and not self._make_room(event):
            return False
        self._items.append(event)
        self._readable.set()
        return True

    async def put(self, event: JobEvent) -> None:
        """Add an event, waiting for room only when coalescing cannot make any."""
        while not self.offer(event):
            self._writable.clear()
            await self._writable.wait()

    def get_nowait(self) -> JobEvent | None:
        """The oldest queued event, or None when the queue is empty."""
        if not self._items:
            return None
        event = self._items.popleft()
        self._writable.set()
        return event

    async def get(self) -> JobEvent | None:
        """The oldest event, waiting for one; None once the queue is closed and empty."""
        while not self._items:
            if self._closed:
                return None
            self._readable.clear()
            await self._readable.wait()
        return self.get_nowait()

    def drain(self) -> list[JobEvent]:
        """Every queued event, oldest first (empties the queue)."""
        out = list(self._items)
        self._items.clear()
        self._writable.set()
        return out

    def close(self) -> None:
        """No more events will be offered; readers get None after the last one."""
        self._closed = True
        self._readable.set()

    def _make_room(self, incoming: JobEvent) -> bool:
        """Drop queued solutions older than the newest solution; True when any was dropped."""
        positions = [i for i, e in enumerate(self._items) if e.type == EventType.solution]
        if incoming.type != EventType.solution:
            positions = positions[:-1]  # the newest queued solution stays
        if not positions:
            return False
        drop = set(positions)
        self._items = deque(e for i, e in enumerate(self._items) if i not in drop)
        self.dropped += len(drop)
        return True


async def pump(events: AsyncIterator[JobEvent], queue: EventQueue) -> None:
    """Move a backend's event iterator into a queue, closing the queue at the end (or on error)."""
    try:
        async for event in events:
            await queue.put(event)
    finally:
        queue.close()
        aclose = getattr(events, "aclose", None)
        if aclose is not None:
            await aclose()
