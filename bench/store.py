"""Benchmark: loading a big graph database (old ``.npz`` against memory-mapped ``.npy``) and S3 round trips.

Prints one JSON object per line:

* ``{"bench": "build", ...}`` — a graph database of about ``--frames`` frames (default 100,000) built
  once as ``bench/graph_scale.py`` builds it (Bandai-Namco clips + copies) and kept as an ``.npz`` in
  ``~/.cache/segue/bench-store/`` (later runs reuse it: run the build niced, once).
* ``{"bench": "load", "layout": "npz" | "npy-mmap", ...}``: in a fresh process each: the seconds to
  turn the stored database into a loaded ``GraphEngine`` (``load_s``, and ``load_cpu_s`` of process
  CPU: the npz is read and inflated into memory; the npy files are memory-mapped, so the engine's
  own derivations are what is left), and the process's memory after the load, from
  ``/proc/PID/smaps_rollup``: ``rss_mb`` (resident), ``pss_mb`` (resident with shared pages split
  between their users), ``private_mb`` (pages only this process maps: for the only mapper this
  includes the database file's pages it touched, and the heap it keeps for reuse, see
  :mod:`motion.allocator`) and ``shared_mb`` (pages another process maps too: the database's file
  pages, one copy in the page cache, and the interpreter's libraries). ``processes: 1`` is one
  engine process alone; ``processes: 2`` are two engine processes holding the same database, each
  measured while both hold it (``process`` 1 and 2): a second engine costs its ``private_mb``.
  ``frames`` and ``tree_nodes`` give the database's size.
* ``{"bench": "s3", ...}`` — against a ``moto_server`` this script starts (an S3-protocol server on
  localhost, so the figures are the protocol's and boto3's overhead, not a network's): median
  milliseconds of a 1 KiB put and get, the upload of the database (``put_database_arrays``, MB/s),
  a worker's first ``database_dir`` (download into its disk cache, MB/s) and a cached one, and
  reading the budget facts lazily (a few small arrays, as the API does).

``load_avg`` is the 1-minute load average at the start (a shared machine slows everything down).
Usage: ``nice -n 10 python bench/store.py [--frames 100000]``; ``--npz FILE`` loads a database kept by
``bench/graph_scale.py --keep`` instead of building one, ``--code DIR`` loads it with the Segue checkout
in ``DIR`` (e.g. the main checkout, to compare the engine's load before and after a change).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

CACHE = Path.home() / ".cache" / "segue" / "bench-store"


def memory_mb(pid: int | str = "self") -> dict[str, float]:
    """Resident, proportional, private and shared memory of a process (MiB, smaps_rollup)."""
    fields: dict[str, float] = {}
    with open(f"/proc/{pid}/smaps_rollup", encoding="ascii") as fh:
        for line in fh:
            parts = line.split()
            if len(parts) >= 2 and parts[0].endswith(":") and parts[1].isdigit():
                fields[parts[0][:-1]] = int(parts[1]) / 1024.0
    private = fields.get("Private_Clean", 0.0) + fields.get("Private_Dirty", 0.0)
    return {
        "rss_mb": round(fields.get("Rss", 0.0), 1),
        "pss_mb": round(fields.get("Pss", 0.0), 1),
        "private_mb": round(private, 1),
        "shared_mb": round(fields.get("Shared_Clean", 0.0) + fields.get("Shared_Dirty", 0.0), 1),
    }


def build(frames: int) -> Path:
    """The cached ``.npz`` of a graph database of about ``frames`` frames (built once)."""
    path = CACHE / f"graph-{frames}.npz"
    if path.exists():
        return path
    from graph_scale import library_of

    from engines.base import CollectingEmitter, foot_floor_arrays
    from engines.graph.engine import GraphEngine
    from engines.library import library_to_arrays
    from engines.registry import parse_database_spec
    from workers.store import npz_bytes

    library, made_of = library_of(frames)
    spec = parse_database_spec({"kind": "graph", "clips": [{"bvh": "x.bvh"}], "candidates": "indexed"})
    t0 = time.perf_counter()
    arrays = library_to_arrays(library)
    arrays.update(GraphEngine.build(spec, library, CollectingEmitter(), lambda: False))
    arrays.update(GraphEngine.quality_reference_of(library, arrays).to_arrays())
    arrays.update(foot_floor_arrays(library, GraphEngine.example_clips(library, arrays)))
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(npz_bytes(arrays))
    tmp.rename(path)
    info = {"bench": "build", "frames": library.total_frames, "made_of": made_of}
    print(json.dumps({**info, "build_s": round(time.perf_counter() - t0, 1)}), flush=True)
    return path


def load_one(layout: str, source: str, hold: bool) -> dict[str, Any]:
    """Load the database into a GraphEngine in this process (``--load`` mode); with ``hold``, print
    the figures and keep the engine until a line comes on stdin."""
    from engines.graph.engine import GraphEngine
    from motion.allocator import tune_process
    from workers.store import Store, load_npz

    tune_process()
    before = memory_mb()
    t0, c0 = time.perf_counter(), time.process_time()
    if layout == "npz":
        arrays = load_npz(Path(source).read_bytes())
    else:
        arrays = Store(source).database_arrays("bench")
    engine = GraphEngine.load(arrays)
    assert isinstance(engine, GraphEngine)
    load_s, load_cpu_s = time.perf_counter() - t0, time.process_time() - c0
    figures = {
        "load_s": round(load_s, 2),
        "load_cpu_s": round(load_cpu_s, 2),
        **memory_mb(),
        "rss_before_mb": before["rss_mb"],
        "frames": engine.library.total_frames,
        "tree_nodes": engine.tree.size,
    }
    if hold:
        print(json.dumps(figures), flush=True)
        sys.stdin.readline()
    del engine
    return figures


def _child(layout: str, source: str, code: str | None, hold: bool) -> list[str]:
    cmd = [sys.executable, __file__, "--load", layout, "--source", source]
    return cmd + (["--code", code] if code else []) + (["--hold"] if hold else [])


def run_load(layout: str, source: str, code: str | None = None) -> dict[str, Any]:
    out = subprocess.run(
        _child(layout, source, code, False), check=True, capture_output=True, text=True
    ).stdout
    return dict(json.loads(out.strip().splitlines()[-1]))


def mapped_loads(source: str, code: str | None = None) -> list[dict[str, Any]]:
    """One engine process loading the memory-mapped database, then a second one while the first
    holds it: the figures of the one, then of both measured while both hold it (from outside)."""
    procs: list[subprocess.Popen[str]] = []
    loads: list[dict[str, Any]] = []
    rows: list[dict[str, Any]] = []
    try:
        for n in (1, 2):
            p = subprocess.Popen(
                _child("npy", source, code, True), stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
            )
            procs.append(p)
            assert p.stdout is not None
            loaded = json.loads(p.stdout.readline())  # it holds the engine now
            loads.append({k: loaded[k] for k in ("load_s", "load_cpu_s", "frames", "tree_nodes")})
            for i, q in enumerate(procs):
                rows.append({"processes": n, "process": i + 1, **loads[i], **memory_mb(q.pid)})
    finally:
        for p in procs:
            if p.stdin is not None:
                p.stdin.write("\n")
                p.stdin.close()
            p.wait()
    for r in rows:
        if r["processes"] == 1:
            del r["process"]
    return rows


def s3_figures(npz: Path) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT))
    from tests.s3server import aws_environment, moto_server, new_bucket
    from workers.budget import database_facts
    from workers.store import Store, load_npz

    arrays = load_npz(npz.read_bytes())
    with moto_server() as endpoint, aws_environment(endpoint), tempfile.TemporaryDirectory() as tmp:
        url = f"s3://{new_bucket(endpoint)}/segue"
        api = Store(url, Path(tmp) / "api")
        small = os.urandom(1024)
        puts, gets = [], []
        for i in range(50):
            t0 = time.perf_counter()
            api.objects.put(f"bench/{i}.bin", small)
            puts.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            api.objects.get(f"bench/{i}.bin")
            gets.append(time.perf_counter() - t0)
        size = sum(a.nbytes for a in arrays.values())
        t0 = time.perf_counter()
        api.put_database_arrays("bench", arrays)
        upload = time.perf_counter() - t0
        worker = Store(url, Path(tmp) / "worker")
        t0 = time.perf_counter()
        worker.database_dir("bench")
        download = time.perf_counter() - t0
        t0 = time.perf_counter()
        worker.database_dir("bench")
        cached = time.perf_counter() - t0
        t0 = time.perf_counter()
        database_facts(api, "bench")
        facts = time.perf_counter() - t0
        return {
            "put_1kib_ms": round(statistics.median(puts) * 1e3, 2),
            "get_1kib_ms": round(statistics.median(gets) * 1e3, 2),
            "database_mb": round(size / 1e6, 1),
            "objects": len(arrays) + 1,
            "upload_s": round(upload, 2),
            "upload_mb_s": round(size / 1e6 / upload, 1),
            "first_download_s": round(download, 2),
            "download_mb_s": round(size / 1e6 / download, 1),
            "cached_database_dir_ms": round(cached * 1e3, 1),
            "api_facts_ms": round(facts * 1e3, 1),
            "api_downloaded_nothing": not (Path(tmp) / "api" / "cache").exists(),
        }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--npz", type=Path, help="a database kept by bench/graph_scale.py --keep (no build)")
    ap.add_argument("--code", help="the Segue checkout the engine processes load with (default: this one)")
    ap.add_argument("--no-s3", action="store_true")
    ap.add_argument("--load", choices=("npz", "npy"), help=argparse.SUPPRESS)
    ap.add_argument("--source", help=argparse.SUPPRESS)
    ap.add_argument("--hold", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.load:
        if args.code:
            sys.path.insert(0, str(Path(args.code).resolve()))
        figures = load_one(args.load, args.source, args.hold)
        if not args.hold:
            print(json.dumps(figures), flush=True)
        return 0
    load_avg = round(os.getloadavg()[0], 2)
    npz = args.npz if args.npz is not None else build(args.frames)
    from workers.store import Store, load_npz

    code = str(Path(args.code).resolve()) if args.code else None
    with tempfile.TemporaryDirectory() as tmp:
        Store(tmp).put_database_arrays("bench", load_npz(npz.read_bytes()))
        info = {"bench": "load", "code": code or str(ROOT), "load_avg": load_avg}
        disk = {"npz_mb": round(npz.stat().st_size / 1e6, 1)}
        print(json.dumps({**info, "layout": "npz", **disk, **run_load("npz", str(npz), code)}), flush=True)
        for row in mapped_loads(tmp, code):
            print(json.dumps({**info, "layout": "npy-mmap", **row}), flush=True)
    if not args.no_s3:
        print(json.dumps({"bench": "s3", **s3_figures(npz), "load_avg": load_avg}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
