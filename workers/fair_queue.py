"""Waiting jobs served round-robin by principal: the embedded backend's queue.

One first-in-first-out line per principal (the job's owner; jobs without one share a line) and a
turn that goes round the principals: each :meth:`FairQueue.pop` serves the principal served
longest ago among those with jobs waiting, and that principal goes last. A principal whose line
empties keeps its place in the turn, and one never served comes first, so one
principal's backlog delays another's next job by at most the job each engine process is running.
The Redis backend does the same with one Redis list per principal (:mod:`workers.redis_queue`).
"""

from __future__ import annotations

from collections import OrderedDict, deque
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")


class FairQueue(Generic[T]):
    """Items in per-principal lines, popped round-robin across principals (see the module
    docstring). ``owner_of(item)`` names an item's principal."""

    def __init__(self, owner_of: Callable[[T], str | None], remember: int = 1024) -> None:
        self.owner_of = owner_of
        self.remember = remember
        """Principals kept in the turn while they have nothing waiting (beyond: forgotten)."""
        self._lines: OrderedDict[str, deque[T]] = OrderedDict()
        """Every principal's line in turn order, the one served longest ago first."""

    def __len__(self) -> int:
        return sum(len(line) for line in self._lines.values())

    def __bool__(self) -> bool:
        return any(self._lines.values())

    def __iter__(self) -> Iterator[T]:
        for line in self._lines.values():
            yield from line

    def _line(self, item: T) -> deque[T]:
        owner = self.owner_of(item) or ""
        line = self._lines.get(owner)
        if line is None:
            if len(self._lines) >= self.remember:  # forget the principals with nothing waiting
                for idle in [o for o, waiting in self._lines.items() if not waiting]:
                    del self._lines[idle]
            line = self._lines[owner] = deque()
            self._lines.move_to_end(owner, last=False)  # never served: its turn is first
        return line

    def append(self, item: T) -> None:
        """Queue ``item`` last in its principal's line."""
        self._line(item).append(item)

    def appendleft(self, item: T) -> None:
        """Queue ``item`` first in its principal's line (a job run again)."""
        self._line(item).appendleft(item)

    def pop(self) -> T:
        """The first item of the principal served longest ago that has one; that principal goes
        last in the turn. ``IndexError`` when nothing waits."""
        for owner, line in self._lines.items():
            if line:
                item = line.popleft()
                self._lines.move_to_end(owner)
                return item
        raise IndexError("pop from an empty FairQueue")

    def unpop(self, item: T) -> None:
        """Undo a :meth:`pop` of ``item``: first in its line again, and its principal's turn
        first again."""
        self.appendleft(item)
        self._lines.move_to_end(self.owner_of(item) or "", last=False)

    def remove(self, item: T) -> None:
        """Take ``item`` out of the queue (``ValueError`` when it is not in it)."""
        line = self._lines.get(self.owner_of(item) or "")
        if line is None:
            raise ValueError("item not queued")
        line.remove(item)
