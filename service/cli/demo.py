"""``segue demo [ENGINE]``: the engines end to end on bundled clips (:mod:`service.demos`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def cmd_demo(args: argparse.Namespace) -> int:
    from ..demos import DEMOS, run_classic, run_demo

    out = Path(args.out)
    if args.engine is None:
        run_classic(out, synth=not args.no_synth)
        return 0
    names = list(DEMOS) if args.engine == "all" else [args.engine]
    results = [run_demo(name, out) for name in names]
    if len(results) > 1:
        done = [f"{r.name} {'ok' if r.ok else 'NOT ok'} {r.total_s:.1f} s" for r in results]
        print("demos: " + ", ".join(done))
    return 0
