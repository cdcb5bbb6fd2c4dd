"""Benchmark: annotated (and rhythm) database builds from 100k to 1M frames; one JSON line per size.

Needs ``../shared/data/bandai-namco``. The library of a size is :func:`bench.graph_scale.library_of`'s
(every clip of both sets, 85,981 frames at 30 fps, then mirrored and time-scaled copies clip by
clip). Labels: ``--labelled`` (3) clips per label of the real data carry their file's label (the
action of ``dataset-<n>_<action>_<style>_<k>.bvh``) over the whole clip; every other clip and copy
is labelled by propagation, as in ``bench/annotations.py``'s build. Each size is built in a fresh
process (so ``peak_rss_build_mb`` is its own) doing what a worker does for an annotated database
(``AnnotationEngine.build``, the library arrays, quality reference and foot floor):

* ``build_cpu_s`` (process CPU, all threads) and ``build_s`` (wall), and the CPU of each stage
  (``stages_cpu_s``: embedding, SVMs, features and clusters, as reported by the build's progress);
* ``peak_rss_build_mb``: the process's peak resident memory (library included: ``rss_library_mb``);
* ``disk_mb``: the stored database (``workers.store.npz_bytes``); ``bytes_per_frame``.

With ``--kind rhythm`` a rhythm database of the same library's clips of 3 s or more is built
instead (``RhythmEngine.build``; beat analysis needs two beats).
``cpu_exponent`` / ``rss_exponent`` compare consecutive sizes. ``load_avg`` is the 1-minute load
average at the start (wall times carry others' load; CPU times move less).

Run big sizes with ``nice -n 10``, one at a time:
``nice -n 10 python bench/annotations_scale.py --sizes 100000,400000``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.graph_scale import DATA, library_of  # noqa: E402

ACTION = re.compile(r"dataset-\d_(?P<label>[a-z-]+?)_(?P<style>[a-z-]+)_\d+$")


def rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def labelled(library: Any, per_label: int, seed: int = 0) -> Any:
    """``library`` with ``per_label`` real clips of each action labelled by their file's action
    (picked at random with ``seed``; copies are never labelled)."""
    from engines.library import MotionLibrary

    actions = [ACTION.match(n) for n in library.names]
    by_label: dict[str, list[int]] = {}
    for i, m in enumerate(actions):
        if m is not None:
            by_label.setdefault(m.group("label"), []).append(i)
    rng = np.random.default_rng(seed)
    chosen = {int(i): lab for lab, idx in sorted(by_label.items()) for i in rng.permutation(idx)[:per_label]}
    labels = tuple(
        ({"label": chosen[i], "start": 0, "end": m.num_frames, "value": 1},) if i in chosen else ()
        for i, m in enumerate(library.motions)
    )
    return MotionLibrary(library.names, library.motions, labels)


def long_clips(library: Any, seconds: float) -> Any:
    """The clips of ``library`` of at least ``seconds``."""
    from engines.library import MotionLibrary

    keep = [i for i, m in enumerate(library.motions) if m.num_frames >= seconds * m.fps]
    return MotionLibrary(
        tuple(library.names[i] for i in keep),
        tuple(library.motions[i] for i in keep),
        tuple(library.labels[i] for i in keep),
    )


class StageEmitter:
    """Records the process CPU time at every progress message (the build's stages)."""

    def __init__(self) -> None:
        self.marks: list[tuple[str, float, float]] = []

    def progress(self, fraction: float, message: str = "") -> None:
        self.marks.append((message, time.process_time(), rss_mb()))

    def solution(self, solution: Any) -> str:
        return ""


def stages(marks: list[tuple[str, float, float]], c0: float, c1: float) -> dict[str, Any]:
    """CPU seconds of each stage of the build (from the progress message that starts it to the
    next stage's; ``rest``: the library arrays, quality reference and foot floor after the build's
    last message), and the peak RSS when each stage ended."""
    starts = (
        ("embedding frames", "embed"),
        ("propagating labels", "svm"),
        ("continuity features", "features"),
        ("clustering blocks", "clusters"),
    )
    cpu: dict[str, float] = {}
    rss: dict[str, float] = {}
    stage, since = "setup", c0
    for message, at, peak in marks:
        name = next((k for p, k in starts if message.startswith(p)), None)
        if name is None:
            continue
        cpu[stage] = round(cpu.get(stage, 0.0) + at - since, 1)
        rss[stage] = round(peak, 1)
        stage, since = name, at
    cpu[stage] = round(cpu.get(stage, 0.0) + c1 - since, 1)
    return {"stages_cpu_s": cpu, "stages_peak_rss_mb": rss}


def build_one(frames: int, kind: str, per_label: int, spec_extra: dict[str, Any]) -> dict[str, Any]:
    """Build the library of ``frames`` as a worker does and measure it (module docstring)."""
    from engines.registry import kind_class, parse_database_spec
    from motion.allocator import tune_process
    from workers.store import npz_bytes

    tune_process()  # as every Segue process does
    load_avg = os.getloadavg()[0]
    library, made_of = library_of(frames)
    if kind == "rhythm":  # beat analysis needs two beats: clips of 3 s or more
        library, made_of = long_clips(library, 3.0), f"clips of 3 s or more of: {made_of}"
    library = labelled(library, per_label)
    rss_library = rss_mb()
    engine = kind_class(kind)
    clips = [{"bvh": f"{i}.bvh"} for i in range(len(library.names))]
    spec = parse_database_spec({"kind": kind, "clips": clips, **spec_extra})
    rec = StageEmitter()
    c0, t0 = time.process_time(), time.perf_counter()
    arrays = engine.library_arrays(spec, library, rec, lambda: False)  # type: ignore[arg-type]
    build_cpu, build_s = time.process_time() - c0, time.perf_counter() - t0
    peak = rss_mb()
    disk = len(npz_bytes(arrays))
    out: dict[str, Any] = {
        "kind": kind,
        "frames": library.total_frames,
        "clips": len(library.names),
        "labelled_clips": sum(1 for lb in library.labels if lb),
        "made_of": made_of,
        "build_cpu_s": round(build_cpu, 1),
        "build_s": round(build_s, 1),
        "peak_rss_build_mb": round(peak, 1),
        "rss_library_mb": round(rss_library, 1),
        "build_rss_over_library_mb": round(peak - rss_library, 1),
        "disk_mb": round(disk / 1e6, 1),
        "bytes_per_frame": round(disk / library.total_frames),
        "load_avg": round(load_avg, 2),
    }
    if kind == "annotated":
        out.update(stages(rec.marks, c0, c0 + build_cpu))
        report = json.loads(str(arrays["ann.report"]))
        out["support_vectors"] = {m["label"]: m["support_vectors"] for m in report}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="100000,400000", help="frames, comma-separated")
    ap.add_argument("--kind", default="annotated", choices=("annotated", "rhythm"))
    ap.add_argument("--labelled", type=int, default=3, help="labelled real clips per label")
    ap.add_argument("--spec", type=json.loads, default={}, help="other spec settings (JSON object)")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)  # one build in this process
    args = ap.parse_args(argv)
    if not DATA.exists():
        print(json.dumps({"skipped": f"no data at {DATA}"}))
        return 0
    if args.one:
        print(json.dumps(build_one(args.one, args.kind, args.labelled, args.spec)))
        return 0
    previous: dict[str, Any] | None = None
    for size in (int(s) for s in args.sizes.split(",")):
        cmd = [
            sys.executable,
            __file__,
            "--one",
            str(size),
            "--kind",
            args.kind,
            "--labelled",
            str(args.labelled),
            "--spec",
            json.dumps(args.spec),
        ]
        done = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
        out = dict(json.loads(done.strip().splitlines()[-1]))
        if previous is not None:
            ratio = np.log(out["frames"] / previous["frames"])
            out["cpu_exponent"] = round(
                float(np.log(out["build_cpu_s"] / previous["build_cpu_s"]) / ratio), 3
            )
            out["rss_exponent"] = round(
                float(np.log(out["peak_rss_build_mb"] / previous["peak_rss_build_mb"]) / ratio), 3
            )
        print(json.dumps(out), flush=True)
        previous = out
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
