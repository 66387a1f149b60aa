"""The stream fan-out: bounded per-client queues that drop the oldest frame, never block."""

from __future__ import annotations

import asyncio

from backend.streaming.fanout import StreamHub


def test_stalled_client_drops_oldest_and_fast_client_gets_all() -> None:
    async def scenario() -> tuple[list[str | None], list[str | None], int]:
        hub = StreamHub(queue_frames=3)
        stalled = hub.subscribe()
        fast = hub.subscribe()
        got_fast: list[str | None] = []
        for k in range(10):
            hub.publish(f"f{k}")
            got_fast.append(await fast.queue.get())  # the fast client keeps up
        hub.close()
        got_fast.append(await fast.queue.get())
        stalled_items = [stalled.queue.get_nowait() for _ in range(stalled.queue.qsize())]
        return got_fast, stalled_items, stalled.dropped

    got_fast, stalled_items, dropped = asyncio.run(scenario())
    assert got_fast == [f"f{k}" for k in range(10)] + [None]
    # queue of 3: the stalled client keeps the two newest frames and the end marker;
    # 10 frames + 1 marker - 3 kept = 8 dropped
    assert stalled_items == ["f8", "f9", None]
    assert dropped == 8


def test_late_subscriber_starts_with_latest_frame_and_sees_end() -> None:
    async def scenario() -> list[str | None]:
        hub = StreamHub(queue_frames=4)
        hub.publish("a")
        hub.publish("b")
        hub.close()
        sub = hub.subscribe()
        return [sub.queue.get_nowait() for _ in range(sub.queue.qsize())]

    assert asyncio.run(scenario()) == ["b", None]


def test_publish_with_many_stalled_clients_is_cheap() -> None:
    """publish() only touches in-memory queues: 100 stalled clients x 1000 frames stay bounded."""
    import time

    async def scenario() -> tuple[float, int]:
        hub = StreamHub(queue_frames=2)
        subs = [hub.subscribe() for _ in range(100)]
        t0 = time.perf_counter()
        for k in range(1000):
            hub.publish(str(k))
        return time.perf_counter() - t0, max(s.queue.qsize() for s in subs)

    elapsed, max_q = asyncio.run(scenario())
    assert max_q == 2  # bounded by queue_frames
    # 1e5 put/get pairs in pure Python take ~0.1 s; 2 s leaves room for a loaded 2-core machine
    assert elapsed < 2.0
