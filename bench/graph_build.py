"""Benchmark: the motion-graph build (``engines.graph.build.build_graph``) on Bandai-Namco data.

Needs ``../shared/data/bandai-namco``. For every set (``--sets``), in a fresh process (so the peak
resident memory is that set's alone), loads the clips at 30 fps (``engines.library.build_library``),
builds the graph with ``--tau`` and prints one JSON line:

``{"set", "frames", "clips", "leaf_edges", "root_edges", "tree_nodes", "dropped_clips", "load_s",
"build_s", "features_s", "scan_s", "rss_before_build_mb", "peak_rss_mb", "load_avg"}``

Sets:

* ``loco``: dataset-2 walk, walk-turn-left/right and run (145 clips, ~21.8k frames; the set of
  ``bench/graph.py``).
* ``mix``: dataset-2 walk and turns, plus every fourth clip of its actions (raise-up-*, wave-*)
  (~21k frames).
* ``all``: every clip of dataset-1 and dataset-2 (639 clips, ~86k frames; one skeleton).
* ``hierarchy``: no data; the edge hierarchy alone (``engines.graph.hierarchy.build_hierarchy``) over
  200,000 random leaf edges among 60 clips of 2,000 frames, printing ``{"set", "leaf_edges",
  "tree_nodes", "hierarchy_s", "peak_rss_mb", "load_avg"}`` (the scale
  tests/engines/test_graph_build.py checks for correctness, without a clock).

``build_s`` is the build alone (features, scan, pruning, hierarchy, tracks), not the BVH loading
(``load_s``); ``peak_rss_mb`` is the process's peak (loading included). ``load_avg`` is the 1-minute
load average at the start: on a shared machine other work slows the figures down.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DATA = ROOT.parent / "shared" / "data" / "bandai-namco"


def files_of(name: str) -> list[str]:
    d1, d2 = DATA / "dataset-1", DATA / "dataset-2"

    def kind(folder: Path, k: str) -> list[str]:
        return sorted(glob.glob(str(folder / f"{folder.name}_{k}_normal_*.bvh")))

    if name == "loco":
        return [f for k in ("walk", "walk-turn-left", "walk-turn-right", "run") for f in kind(d2, k)]
    if name == "mix":
        walks = [f for k in ("walk", "walk-turn-left", "walk-turn-right") for f in kind(d2, k)]
        acts = ("raise-up-both-hands", "raise-up-left-hand", "raise-up-right-hand", "wave-both-hands")
        actions = [f for k in (*acts, "wave-left-hand", "wave-right-hand") for f in kind(d2, k)[::4]]
        return walks + actions
    if name == "all":
        return sorted(glob.glob(str(d1 / "*.bvh"))) + sorted(glob.glob(str(d2 / "*.bvh")))
    raise SystemExit(f"unknown set {name!r} (loco, mix, all)")


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_one(name: str, tau: float) -> dict[str, Any]:
    from engines.base import CollectingEmitter
    from engines.graph.build import build_graph
    from engines.library import ClipInput, build_library
    from motion.allocator import tune_process

    tune_process()  # as every Segue process does
    load_avg = os.getloadavg()[0]
    files = files_of(name)
    t0 = time.perf_counter()
    lib = build_library([ClipInput(Path(f).stem, Path(f).read_bytes()) for f in files], fps=30.0)
    load_s = time.perf_counter() - t0
    before = rss_mb()
    spec = SimpleNamespace(
        tau=tau, joint_weights={}, velocity_weight=1.0, min_jump_frames=10, candidates="auto"
    )
    t0 = time.perf_counter()
    arrays = build_graph(spec, lib, CollectingEmitter(), lambda: False)
    build_s = time.perf_counter() - t0
    report = json.loads(str(arrays["graph.report"]))
    return {
        "set": name,
        "frames": report["frames"],
        "clips": report["clips"],
        "leaf_edges": report["leaf_edges"],
        "root_edges": report["root_edges"],
        "tree_nodes": report["tree_nodes"],
        "dropped_clips": len(report["dropped_clips"]),
        "load_s": round(load_s, 2),
        "build_s": round(build_s, 2),
        "features_s": report["features_s"],
        "scan_s": report["scan_s"],
        "rss_before_build_mb": round(before, 1),
        "peak_rss_mb": round(rss_mb(), 1),
        "load_avg": round(load_avg, 2),
        "tau": tau,
    }


def run_hierarchy(k: int = 200_000) -> dict[str, Any]:
    import numpy as np

    from engines.graph.hierarchy import LeafEdges, build_hierarchy

    load_avg = os.getloadavg()[0]
    rng = np.random.default_rng(2)
    raw = np.stack(
        (rng.integers(0, 60, k), rng.integers(0, 2000, k), rng.integers(0, 60, k), rng.integers(0, 2000, k))
    )
    key = np.unique(raw.T, axis=0)
    leaves = LeafEdges(key[:, 0], key[:, 1], key[:, 2], key[:, 3], rng.random(len(key)))
    t0 = time.perf_counter()
    tree = build_hierarchy(leaves)
    hierarchy_s = time.perf_counter() - t0
    return {
        "set": "hierarchy",
        "leaf_edges": int(leaves.size),
        "tree_nodes": int(tree.size),
        "hierarchy_s": round(hierarchy_s, 2),
        "peak_rss_mb": round(rss_mb(), 1),
        "load_avg": round(load_avg, 2),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", default="loco,mix,all", help="comma-separated: loco, mix, all, hierarchy")
    ap.add_argument("--tau", type=float, default=1.0)
    ap.add_argument("--one", help=argparse.SUPPRESS)  # run one set in this process
    args = ap.parse_args(argv)
    if args.one == "hierarchy":
        print(json.dumps(run_hierarchy()))
        return 0
    if not DATA.exists() and args.sets != "hierarchy":
        print(json.dumps({"skipped": f"no data at {DATA}"}))
        return 0
    if args.one:
        print(json.dumps(run_one(args.one, args.tau)))
        return 0
    for name in args.sets.split(","):
        cmd = [sys.executable, __file__, "--one", name.strip(), "--tau", str(args.tau)]
        out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        print(out.strip().splitlines()[-1], flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
