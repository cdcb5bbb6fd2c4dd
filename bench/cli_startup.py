"""How fast ``segue`` answers before doing any work, against bare Python on the same interpreter.

Usage: ``python bench/cli_startup.py [--runs N]`` (``segue`` installed: its console script is run
with this interpreter, as its shebang would, so that no pyenv/venv shim is measured). Runs, in turn
(interleaved, so that a change of machine load hits every case alike), ``python -c pass``,
``segue --help``, ``segue COMMAND --help`` for every subcommand, an argument error and, for
comparison, a command that loads a clip; prints one JSON object::

    {"runs", "load_avg", "python": {"min_s", "median_s", "cpu_median_s"}, "cases": {"help":
     {"min_s", "median_s", "over_python_s", "over_python_min_s", "cpu_median_s",
     "cpu_over_python_s"}, "inspect_help": {...}, ...}, "worst_over_python_s",
     "worst_cpu_over_python_s"}

``over_python_s`` is the case's median minus bare Python's median (``over_python_min_s`` the same
for the fastest runs); ``cpu_*`` are the same for the process's CPU time (user + system), which a
busy machine changes far less than the wall-clock figures; ``worst_over_python_s`` the
largest of those over ``--help``, the subcommands' ``--help`` and the argument error (the bar:
0.1 s; tests/service/test_cli_startup.py keeps the imports that decide it from coming back, without
a clock). ``load_avg`` is the 1-minute load average at the start.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from service.cli import build_parser  # noqa: E402  (standard library only at import)


def segue_script() -> str:
    """The ``segue`` console script of this interpreter's environment (else the one on PATH)."""
    beside = Path(sys.executable).parent / "segue"
    found = str(beside) if beside.exists() else shutil.which("segue")
    if found is None:
        raise SystemExit("segue is not installed (pip install -e .)")
    return found


def children_cpu_s() -> float:
    """User + system CPU seconds of this process's finished children so far."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def subcommands() -> list[str]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=15)
    args = ap.parse_args()
    segue = [sys.executable, segue_script()]
    cases: dict[str, list[str]] = {"python": [sys.executable, "-c", "pass"], "help": [*segue, "--help"]}
    for name in subcommands():
        cases[f"{name.replace('-', '_')}_help"] = [*segue, name, "--help"]
    cases["argument_error"] = [*segue, "demo", "dance"]
    cases["inspect_sample"] = [*segue, "inspect", "sample:walk", "--json"]
    times: dict[str, list[float]] = {name: [] for name in cases}
    cpu: dict[str, list[float]] = {name: [] for name in cases}
    load_avg = os.getloadavg()[0]
    for _ in range(args.runs):
        for name, argv in cases.items():
            c0 = children_cpu_s()
            t0 = time.perf_counter()
            subprocess.run(argv, capture_output=True, check=False, cwd=ROOT)
            times[name].append(time.perf_counter() - t0)
            cpu[name].append(children_cpu_s() - c0)
    python, python_cpu = times.pop("python"), cpu.pop("python")
    bare, bare_cpu = statistics.median(python), statistics.median(python_cpu)
    out: dict[str, object] = {
        "runs": args.runs,
        "load_avg": round(load_avg, 2),
        "python": {
            "min_s": round(min(python), 3),
            "median_s": round(bare, 3),
            "cpu_median_s": round(bare_cpu, 3),
        },
    }
    summary = {
        name: {
            "min_s": round(min(ts), 3),
            "median_s": round(statistics.median(ts), 3),
            "over_python_s": round(statistics.median(ts) - bare, 3),
            "over_python_min_s": round(min(ts) - min(python), 3),
            "cpu_median_s": round(statistics.median(cpu[name]), 3),
            "cpu_over_python_s": round(statistics.median(cpu[name]) - bare_cpu, 3),
        }
        for name, ts in times.items()
    }
    out["cases"] = summary
    answers = [v for k, v in summary.items() if k != "inspect_sample"]
    out["worst_over_python_s"] = max(v["over_python_s"] for v in answers)
    out["worst_cpu_over_python_s"] = max(v["cpu_over_python_s"] for v in answers)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
