"""Processes of a worker as Linux shows them (``/proc``), for the tests and benches that kill,
freeze or watch a worker's engine processes."""

from __future__ import annotations

from pathlib import Path


def engine_children(pid: int) -> list[int]:
    """The pids of process ``pid``'s children (of every thread) other than ``multiprocessing``'s
    resource tracker: a worker's engine processes."""
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids = (task / "children").read_text().split()
        except OSError:
            continue
        for kid in kids:
            try:
                cmd = Path(f"/proc/{kid}/cmdline").read_bytes()
            except OSError:
                continue
            if b"resource_tracker" not in cmd:
                out.append(int(kid))
    return out
