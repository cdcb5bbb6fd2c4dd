"""Benchmark: how fast the front end shows a first solution, in headless Chromium against the real
service (the figures the browser tests record; the tests themselves assert no times).

Usage: ``python bench/browser.py [-k EXPR]`` (needs /usr/bin/chromium and playwright, as the
browser tests). Runs ``pytest tests/web/test_browser.py`` (``-k`` selects tools, e.g. ``path or
partner``) with ``SEGUE_WEB_TIMINGS`` pointing at a temporary file, then prints one JSON object::

    {"load_avg", "tests_passed", "tools": {TOOL: {"cold_drawn_ms", "warm_drawn_ms", "event_ms",
     "engine_elapsed_ms", "page_work_ms", "frames"}}, "bars": {...}, "within_bars": bool}

per tool (constraints, path, partner, timeline, music, music-live): ``cold_drawn_ms`` from pressing
the button to the first solution drawn, the database not yet loaded in a worker;
``warm_drawn_ms`` the same pressed again (the database loaded; for music-live, the first beat of
the live session); ``event_ms`` the same to the solution's event; ``engine_elapsed_ms`` the
engine's own time to it; ``page_work_ms`` the page's parse + draw of the result. The bars:
``warm_drawn_ms`` <= 1000, ``page_work_ms`` <= 400. ``load_avg`` is the 1-minute load average at
the start: on a busy machine the figures grow (that is why they are a bench, not a test).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
BARS = {"warm_drawn_ms": 1000.0, "page_work_ms": 400.0}


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, float | None]]:
    """Per tool: its cold and warm first-solution figures (the last of each, if run twice)."""
    tools: dict[str, dict[str, float | None]] = {}
    for row in rows:
        t = tools.setdefault(row["tool"], {})
        if row.get("live"):
            t["warm_drawn_ms"] = row["drawn_ms"]
            continue
        t["cold_drawn_ms" if not row["warm"] else "warm_drawn_ms"] = row["drawn_ms"]
        if row["warm"]:
            t["event_ms"] = row["event_ms"]
            t["engine_elapsed_ms"] = row["engine_elapsed_ms"]
        t["page_work_ms"] = round(max(t.get("page_work_ms") or 0.0, row["parse_ms"] + row["draw_ms"]), 1)
        t["frames"] = row["frames"]
    return tools


def within_bars(tools: dict[str, dict[str, float | None]]) -> bool:
    """Every figure recorded is within its bar (False when nothing was recorded)."""
    return bool(tools) and all(
        (value := figures.get(name)) is None or value <= bar
        for figures in tools.values()
        for name, bar in BARS.items()
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-k", default="", help="pytest -k expression selecting the tools' tests")
    args = ap.parse_args()
    load_avg = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        timings = Path(tmp) / "timings.jsonl"
        env = os.environ | {
            "SEGUE_WEB_TIMINGS": str(timings),
            "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
        }
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/web/test_browser.py"]
        argv = [*cmd, *(["-k", args.k] if args.k else [])]
        run = subprocess.run(argv, cwd=ROOT, env=env, stdout=sys.stderr, check=False)  # JSON alone on stdout
        rows = [json.loads(line) for line in timings.read_text().splitlines()] if timings.exists() else []
    tools = summarise(rows)
    print(
        json.dumps(
            {
                "load_avg": round(load_avg, 2),
                "tests_passed": run.returncode == 0,
                "tools": tools,
                "bars": BARS,
                "within_bars": within_bars(tools),
            }
        )
    )


if __name__ == "__main__":
    main()
