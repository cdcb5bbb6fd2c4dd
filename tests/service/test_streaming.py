"""The per-socket event queue: bounded, coalescing solutions for slow clients, never losing the rest."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import pytest

from schemas import EventType, JobEvent
from service.streaming import EventQueue, pump


def ev(i: int, type_: str) -> JobEvent:
    return JobEvent(id=i, job="j", type=EventType(type_), time=float(i), data={"result": f"r{i}"})


def ids(events: list[JobEvent]) -> list[int]:
    return [e.id for e in events]


def test_room_means_every_event_is_kept() -> None:
    q = EventQueue(8)
    for i, t in enumerate(["queued", "started", "solution", "solution", "progress", "solution"], start=1):
        assert q.offer(ev(i, t))
    assert ids(q.drain()) == [1, 2, 3, 4, 5, 6] and q.dropped == 0


def test_full_queue_keeps_only_the_newest_solution() -> None:
    q = EventQueue(4)
    for i, t in enumerate(["queued", "started", "solution", "solution"], start=1):
        assert q.offer(ev(i, t))
    assert q.offer(ev(5, "solution"))  # full: solutions 3 and 4 make way for 5
    assert ids(list(q._items)) == [1, 2, 5] and q.dropped == 2
    assert q.offer(ev(6, "progress"))  # room again
    assert q.offer(ev(7, "solution"))  # full: 5 is older than 7
    assert ids(q.drain()) == [1, 2, 6, 7] and q.dropped == 3


def test_non_solution_event_drops_older_solutions_but_keeps_the_newest() -> None:
    q = EventQueue(4)
    for i, t in enumerate(["started", "solution", "solution", "solution"], start=1):
        assert q.offer(ev(i, t))
    assert q.offer(ev(5, "done"))  # the terminal event is never lost; solution 4 stays as the newest
    assert ids(q.drain()) == [1, 4, 5]


def test_full_of_events_that_must_not_drop_means_backpressure() -> None:
    q = EventQueue(3)
    for i, t in enumerate(["queued", "started", "progress"], start=1):
        assert q.offer(ev(i, t))
    assert not q.offer(ev(4, "progress"))
    assert not q.offer(ev(4, "solution"))
    q2 = EventQueue(3)
    for i, t in enumerate(["started", "progress", "solution"], start=1):
        assert q2.offer(ev(i, t))
    assert not q2.offer(ev(4, "cancelled"))  # the only solution is the newest: nothing to drop
    assert q2.get_nowait() is not None and q2.offer(ev(4, "cancelled"))
    assert ids(q2.drain()) == [2, 3, 4]


def test_queue_bound_is_checked() -> None:
    with pytest.raises(ValueError, match="at least 2"):
        EventQueue(1)


def test_slow_consumer_gets_newest_solution_and_every_other_event() -> None:
    """A producer far ahead of the consumer: solutions coalesce, the rest arrives in order."""
    n = 200
    script = ["queued", "started"] + ["progress" if i % 50 == 0 else "solution" for i in range(n)] + ["done"]
    events = [ev(i, t) for i, t in enumerate(script, start=1)]

    async def source() -> AsyncIterator[JobEvent]:
        for e in events:
            yield e

    async def main() -> tuple[list[JobEvent], int]:
        q = EventQueue(4)
        producer = asyncio.create_task(pump(source(), q))
        got: list[JobEvent] = []
        while (e := await q.get()) is not None:
            got.append(e)
            await asyncio.sleep(0.001)  # slow client
        await producer
        return got, q.dropped

    got, dropped = asyncio.run(main())
    kinds = [e.type.value for e in got]
    assert kinds[:2] == ["queued", "started"] and kinds[-1] == "done"
    assert [e.id for e in got if e.type != EventType.solution] == [
        e.id for e in events if e.type != EventType.solution
    ]
    assert ids(got) == sorted(ids(got))  # still in order
    last_solution = max(e.id for e in events if e.type == EventType.solution)
    assert last_solution in ids(got)  # the newest solution always reaches the client
    assert dropped > 150 and len(got) + dropped == len(events)


def test_blocked_producer_resumes_when_the_consumer_reads() -> None:
    async def main() -> list[int]:
        q = EventQueue(2)

        async def source() -> AsyncIterator[JobEvent]:
            for i, t in enumerate(["queued", "started", "progress", "done"], start=1):
                yield ev(i, t)

        producer = asyncio.create_task(pump(source(), q))
        await asyncio.sleep(0.01)
        assert len(q) == 2 and not producer.done()  # waiting for room
        out = []
        while (e := await q.get()) is not None:
            out.append(e.id)
        await producer
        return out

    assert asyncio.run(main()) == [1, 2, 3, 4]
