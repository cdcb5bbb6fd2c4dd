"""Benchmark: what numba's compile costs a first user and a fresh worker, and what warming saves.

Each figure is one fresh process (``python -m service.cli ...``), wall and CPU (user + sys of the
child) seconds, with ``NUMBA_CACHE_DIR`` pointed at a fresh temporary directory for *cold* and at
the same directory afterwards for *warm*:

``{"demo_control": {"cold": {"wall_s", "cpu_s"}, "warm": {...}, "cold_over_warm": x},
"warm_command": {"cold": {...}, "warm": {...}}, "demo_control_after_warm": {...},
"first_control_job": {"cold": {...}, "after_warm": {...}, "cold_over_warm": x}, "load": [1, 5, 15 min]}``

* ``demo_control`` -- ``segue demo control`` (database build + synthesis + files) with an empty
  cache, then again;
* ``warm_command`` -- ``segue warm`` (what ``segue serve`` / ``segue worker`` run at start and
  the Docker image at build) with an empty cache, then again;
* ``demo_control_after_warm`` -- ``segue demo control`` with a cache that ``segue warm`` filled;
* ``first_control_job`` -- ``segue synth`` of the control demo's request against its built
  database (a fresh worker's first control job) with an empty cache, and after ``segue warm``.

Run it with ``nice`` on a quiet machine; the load average is printed beside the figures.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def timed(args: list[str], cache: Path, cwd: Path) -> dict[str, float]:
    """Wall and CPU seconds of ``python -m service.cli ARGS`` with numba's cache at ``cache``."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "service.cli", *args], cwd=cwd, env=env, check=True, capture_output=True
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2)}


def ratio(cold: dict[str, float], warm: dict[str, float]) -> float:
    return round(cold["wall_s"] / warm["wall_s"], 2)


def main() -> int:
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        demo = ["demo", "control", "--out", str(work / "demo")]
        a, b = work / "cache-a", work / "cache-b"
        cold = timed(demo, a, work)
        warm = timed(demo, a, work)
        out["demo_control"] = {"cold": cold, "warm": warm, "cold_over_warm": ratio(cold, warm)}
        out["warm_command"] = {"cold": timed(["warm"], b, work), "warm": timed(["warm"], b, work)}
        after = timed(demo, b, work)
        out["demo_control_after_warm"] = after | {"over_warm": ratio(after, warm)}
        folder = work / "demo" / "control"
        synth = [
            "synth",
            str(folder / "request.json"),
            "--db",
            str(work / "db"),
            "--out",
            str(work / "out.bvh"),
        ]
        timed(["build", str(folder / "db.json"), "--out", str(work / "db")], a, work)
        first_cold = timed(synth, work / "cache-c", work)
        first_warm = timed(synth, b, work)
        out["first_control_job"] = {
            "cold": first_cold,
            "after_warm": first_warm,
            "cold_over_warm": ratio(first_cold, first_warm),
        }
    out["load"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
