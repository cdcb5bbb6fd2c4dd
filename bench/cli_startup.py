"""How fast ``segue`` answers before doing any work: ``--help``, an argument error, and (for
comparison) a command that loads a clip.

Usage: ``python bench/cli_startup.py [--runs N]`` with ``segue`` on PATH. Prints one JSON object of
median (and worst) wall-clock seconds per case over ``--runs`` runs (default 9); the issue's bar is
0.3 s for ``--help`` and argument errors.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import time

CASES = {
    "help": ["segue", "--help"],
    "argument_error": ["segue", "demo", "dance"],
    "demo_help": ["segue", "demo", "--help"],
    "inspect_sample": ["segue", "inspect", "sample:walk", "--json"],
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=9)
    args = ap.parse_args()
    if shutil.which("segue") is None:
        raise SystemExit("segue is not on PATH (pip install -e .)")
    out: dict[str, object] = {"runs": args.runs}
    for name, argv in CASES.items():
        times = []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            subprocess.run(argv, capture_output=True, check=False)
            times.append(time.perf_counter() - t0)
        out[f"{name}_s"] = round(statistics.median(times), 3)
        out[f"{name}_worst_s"] = round(max(times), 3)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
