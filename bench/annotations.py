"""Benchmark of the annotation engine on the shared Bandai-Namco data; prints one JSON object.

    python bench/annotations.py [--part all|build|search|propagation|joined] [--datasets 1,2]

* ``build``: build time of an annotated database of the whole set (dataset-1 and dataset-2; labels
  from the file names, ``--labelled`` clips per label labelled, the rest propagated), split into
  parsing and the engine's build; per-frame F1 of the propagated labels on the unlabelled clips.
* ``search``: on that database, the time of one 32/16/8 pass for a 30 s output (median of
  ``--repeats``), and passes / solutions per second in anytime mode (``--budget`` seconds).
* ``propagation``: on dataset-2, per-label and macro per-frame F1 on held-out clips as the number
  of labelled clips per label grows (``--ks``, default 1 to 5; the others held out; clips picked at
  random, ``--trials`` draws), with the build's settings (every frame classified).
* ``joined``: on dataset-2, whether propagation places label *changes* inside clips. Per ``--ks``
  (default 3) and trial, the labelled clips are picked as in ``propagation`` and kept whole; the
  held-out clips are shuffled (seeded by k and trial) and joined in pairs of different labels, the
  second clip turned about +Y and moved on the floor so that it starts at the first one's last
  ground position and heading. The library of labelled + joined clips is embedded and propagated
  with the build's settings; on the joined frames (truth: each half's file label): macro per-frame
  F1, and per-frame accuracy (the true label and no other) within 1 s either side of each join and
  farther from it. Part of ``all``, being cheap: it embeds and propagates a new library per trial,
  about 8 s a trial on one core (19 s with the default 2 trials); ``--ks`` applies to it too.

``--spec '{"context_s": 0}'`` runs any part with other database settings than the spec's defaults.
With ``--spec '{"mirror": true}'`` the build and search parts add every clip's mirror image (labels'
sides exchanged): ``heldout_f1`` stays on the real held-out clips, ``mirror_heldout_f1_macro`` is
the mirror images' (a mirror image is labelled when its clip is). The search part also reports the
best motion's ``label_match`` and quality verdict, and ``sided``: three seeds of a 30 s timeline of
labels that name a side (turn left, raise the right hand, wave the left hand).

Figures are wall-clock on whatever else the machine runs; repeat for stable numbers.
"""

from __future__ import annotations

import argparse
import glob
import json
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engines.annotations.build import SVM_DIMS, build_annotated, embed_library, standardize  # noqa: E402
from engines.annotations.engine import AnnotationEngine, AnnotationSearch  # noqa: E402
from engines.annotations.propagate import Propagation, propagate  # noqa: E402
from engines.base import CollectingEmitter, Run  # noqa: E402
from engines.library import ClipInput, MotionLibrary, build_library, library_to_arrays  # noqa: E402
from motion import rotations as rot  # noqa: E402
from motion.ground import ground_frames  # noqa: E402
from motion.mirror import mirror_label  # noqa: E402
from motion.motion import Motion  # noqa: E402
from schemas.annotations import AnnotatedDatabaseSpec, AnnotationRequest  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "bandai-namco"
NAME = re.compile(r"dataset-\d_(?P<label>[a-z-]+?)_(?P<style>[a-z-]+)_\d+\.bvh$")


def files(datasets: list[str]) -> list[tuple[str, str]]:
    out = []
    for d in datasets:
        for f in sorted(glob.glob(str(DATA / f"dataset-{d}" / "*.bvh"))):
            m = NAME.search(f)
            if m:
                out.append((f, m.group("label")))
    return out


def load(items: list[tuple[str, str]], labelled: set[int]) -> tuple[MotionLibrary, list[str]]:
    raw = [(Path(f).stem, Path(f).read_bytes()) for f, _ in items]
    lib = build_library([ClipInput(n, b) for n, b in raw], 30.0)
    clips = [
        ClipInput(
            n, b, None, [{"label": lab, "start": 0, "end": m.num_frames, "value": 1}] if i in labelled else []
        )
        for i, ((n, b), (_, lab), m) in enumerate(zip(raw, items, lib.motions, strict=True))
    ]
    return build_library(clips, 30.0), [lab for _, lab in items]


def pick_labelled(truth: list[str], per_label: int, rng: np.random.Generator) -> set[int]:
    out: set[int] = set()
    for lab in sorted(set(truth)):
        idx = [i for i, t in enumerate(truth) if t == lab]
        out.update(int(i) for i in rng.permutation(idx)[:per_label])
    return out


def f1_table(
    vocab: list[str], labels: np.ndarray, truth_of_frame: np.ndarray, held: np.ndarray
) -> dict[str, float]:
    out = {}
    for j, lab in enumerate(vocab):
        y = truth_of_frame[held] == lab
        p = labels[held, j] > 0
        tp = float(np.sum(y & p))
        denom = float(y.sum() + p.sum())
        if y.sum() == 0:
            continue
        out[lab] = round(2 * tp / denom, 4) if denom else 0.0
    return out


def clip_accuracy(
    vocab: list[str], labels: np.ndarray, counts: list[int], truth: list[str], held: set[int]
) -> float:
    """Fraction of held-out clips whose most frequent propagated label is their true label."""
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    hits = [
        vocab[int(np.argmax((labels[starts[i] : starts[i] + counts[i]] > 0).mean(axis=0)))] == truth[i]
        for i in sorted(held)
    ]
    return round(float(np.mean(hits)), 4) if hits else 0.0


def bench_build(args: argparse.Namespace) -> tuple[dict[str, Any], AnnotationEngine]:
    items = files(args.datasets.split(","))
    truth = [lab for _, lab in items]
    labelled = pick_labelled(truth, args.labelled, np.random.default_rng(0))
    t0 = time.perf_counter()
    lib, _ = load(items, labelled)
    t_parse = time.perf_counter() - t0
    spec = AnnotatedDatabaseSpec(clips=[{"bvh": Path(f).name} for f, _ in items], **args.spec)
    rec = CollectingEmitter()
    t0 = time.perf_counter()
    lib = AnnotationEngine.library_for(spec, lib)  # with 'mirror': the mirror images follow
    arrays = build_annotated(spec, lib, rec, lambda: False)
    t_build = time.perf_counter() - t0
    arrays.update(library_to_arrays(lib))
    engine = AnnotationEngine(lib, arrays)
    counts = [m.num_frames for m in lib.motions]
    n_real = int(sum(counts[: len(items)]))
    mirrors = len(lib.motions) > len(items)
    # a mirror image's true label is its clip's, sides exchanged; it is labelled when its clip is
    truth_f = np.repeat(np.array(truth + [mirror_label(t) for t in truth] * mirrors), counts)
    held_clips = [i not in labelled for i in range(len(items))]
    held = np.repeat(np.array(held_clips * (2 if mirrors else 1)), counts)
    real = np.arange(truth_f.size) < n_real
    f1 = f1_table(engine.db.vocab, engine.db.labels, truth_f, held & real)
    report = json.loads(str(arrays["ann.report"]))
    extra: dict[str, Any] = {}
    if mirrors:
        f1_mirror = f1_table(engine.db.vocab, engine.db.labels, truth_f, held & ~real)
        extra = {
            "mirror": True,
            "mirror_heldout_f1_macro": round(float(np.mean(list(f1_mirror.values()))), 4),
            "database_frames": int(sum(counts)),
        }
    counts = counts[: len(items)]
    return (
        {
            **extra,
            "clips": len(items),
            "frames": int(sum(counts)),
            "labels": len(engine.db.vocab),
            "labelled_clips_per_label": args.labelled,
            "parse_s": round(t_parse, 2),
            "engine_build_s": round(t_build, 2),
            "heldout_f1": f1,
            "heldout_f1_macro": round(float(np.mean(list(f1.values()))), 4),
            "heldout_clip_accuracy": clip_accuracy(
                engine.db.vocab,
                engine.db.labels,
                counts,
                truth,
                {i for i in range(len(items)) if i not in labelled},
            ),
            "cv": {r["label"]: r["cv"] for r in report},
        },
        engine,
    )


def bench_search(engine: AnnotationEngine, args: argparse.Namespace) -> dict[str, Any]:
    vocab = engine.db.vocab
    want = [x for x in ("walk", "run", "wave-right-hand") if x in vocab] or vocab[:3]
    n = 900
    tl = [{"label": want[0], "start": 0, "end": 450}]
    if len(want) > 1:
        tl.append({"label": want[1], "start": 450, "end": n})
    if len(want) > 2:
        tl.append({"label": want[2], "start": 0, "end": n, "value": -1})
    req = AnnotationRequest(frames=n, timeline=tl, seed=1, footskate=False)
    state = AnnotationSearch(engine.db, req)
    state.one_pass()  # warm-up
    times = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        state.one_pass()
        times.append(time.perf_counter() - t0)
    rec = CollectingEmitter()
    t0 = time.perf_counter()
    engine.search(req, Run(args.budget, emit=rec))
    wall = time.perf_counter() - t0
    best = rec.solutions[-1]
    state2 = AnnotationSearch(engine.db, req)
    t0 = time.perf_counter()
    passes = 0
    while time.perf_counter() - t0 < args.budget:
        state2.one_pass()
        passes += 1
    return {
        "output_frames": n,
        "pass_ms_median": round(1e3 * float(np.median(times)), 1),
        "pass_ms_min": round(1e3 * float(np.min(times)), 1),
        "anytime_budget_s": args.budget,
        "anytime_solutions": len(rec.solutions),
        "anytime_solutions_per_s": round(len(rec.solutions) / wall, 2),
        "passes_per_s": round(passes / (time.perf_counter() - t0), 2),
        "timeline": [f"{e['label']}{'' if e.get('value', 1) == 1 else ' (not)'}" for e in tl],
        "label_match": round(best.metrics["label_match"], 4),
        "label_match_steady": round(best.metrics["label_match_steady"], 4),
        "quality_ok": None if best.quality is None else best.quality.ok,
        "sided": sided_search(engine),
    }


def sided_search(engine: AnnotationEngine) -> dict[str, Any]:
    """The best of 80 passes (seeds 1 to 3) for a 30 s timeline of labels that name a side
    (Bandai-Namco's): turn left, raise the right hand, wave the left hand, each 10 s."""
    want = ("walk-turn-left", "raise-up-right-hand", "wave-left-hand")
    if not all(w in engine.db.vocab for w in want):
        return {}
    tl = [{"label": w, "start": 300 * i, "end": 300 * (i + 1)} for i, w in enumerate(want)]
    out = []
    for seed in (1, 2, 3):
        rec = CollectingEmitter()
        engine.search(AnnotationRequest(frames=900, timeline=tl, seed=seed), Run(600.0, emit=rec))
        best = rec.solutions[-1]
        out.append(
            (
                best.metrics["label_match"],
                best.metrics["label_match_steady"],
                float(best.score),
                None if best.quality is None else best.quality.ok,
            )
        )
    return {
        "timeline": list(want),
        "label_match": [round(o[0], 4) for o in out],
        "label_match_steady": [round(o[1], 4) for o in out],
        "score": [round(o[2], 1) for o in out],
        "quality_ok": [o[3] for o in out],
    }


def propagate_as_built(
    z: np.ndarray,
    clip_of: np.ndarray,
    counts: list[int],
    labels: list[list[dict[str, Any]]],
    spec: AnnotatedDatabaseSpec,
    fps: float,
) -> Propagation:
    """:func:`propagate` with the build's settings (the spec's, every frame classified)."""
    return propagate(
        z,
        clip_of,
        counts,
        labels,
        c=spec.svm_c,
        gammas=spec.gammas,
        smooth_frames=int(round(spec.smooth_s * fps)) | 1,
        exclusive=spec.exclusive,
        switch_cost=spec.switch_s * fps,
        self_training=spec.self_training,
    )


def bench_propagation(args: argparse.Namespace) -> dict[str, Any]:
    items = files(["2"])
    truth = [lab for _, lab in items]
    lib, _ = load(items, set())
    spec = AnnotatedDatabaseSpec(clips=[{"bvh": Path(f).name} for f, _ in items], **args.spec)
    emb, _, _, _ = embed_library(lib, spec)
    z = standardize(emb, SVM_DIMS)
    counts = [m.num_frames for m in lib.motions]
    clip_of = np.repeat(np.arange(len(counts)), counts)
    truth_f = np.repeat(np.array(truth), counts)
    out: dict[str, Any] = {}
    for k in (int(x) for x in (args.ks or "1,2,3,4,5").split(",")):
        macros: list[float] = []
        clip_acc: list[float] = []
        per: list[dict[str, float]] = []
        for trial in range(args.trials):
            labelled = pick_labelled(truth, k, np.random.default_rng(100 * k + trial))
            labels = [
                [{"label": truth[i], "start": 0, "end": counts[i], "value": 1}] if i in labelled else []
                for i in range(len(items))
            ]
            prop = propagate_as_built(z, clip_of, counts, labels, spec, lib.fps)
            held = np.repeat(np.array([i not in labelled for i in range(len(items))]), counts)
            f1 = f1_table(prop.vocab, prop.labels, truth_f, held)
            per.append(f1)
            macros.append(float(np.mean(list(f1.values()))))
            held_clips = {i for i in range(len(items)) if i not in labelled}
            clip_acc.append(clip_accuracy(prop.vocab, prop.labels, counts, truth, held_clips))
        labs = sorted(per[0])
        out[str(k)] = {
            "macro_f1": round(float(np.mean(macros)), 4),
            "clip_accuracy": round(float(np.mean(clip_acc)), 4),
            "per_label": {lab: round(float(np.mean([p[lab] for p in per if lab in p])), 4) for lab in labs},
        }
    return {
        "dataset": "bandai-namco dataset-2",
        "clips": len(items),
        "trials": args.trials,
        "by_labelled_clips": out,
    }


def join(first: Motion, second: Motion) -> Motion:
    """``first`` followed by ``second`` (same skeleton), ``second`` turned about +Y and moved on the
    floor so that its first frame has ``first``'s last ground position and heading."""
    xz1, yaw1 = ground_frames(first)
    xz2, yaw2 = ground_frames(second)
    turn = rot.from_yaw(yaw1[-1] - yaw2[0])
    root = rot.rotate(turn, second.root_positions)
    start = rot.rotate(turn, np.array([xz2[0, 0], 0.0, xz2[0, 1]]))
    root[:, [0, 2]] += xz1[-1] - start[[0, 2]]
    rotations = second.rotations.copy()
    rotations[:, 0] = rot.multiply(turn, second.rotations[:, 0])
    return Motion(
        first.skeleton,
        np.concatenate((first.root_positions, root)),
        np.concatenate((first.rotations, rotations)),
        first.fps,
        np.concatenate((first.joint_translations, second.joint_translations)),
        first.units,
        f"{first.name}+{second.name}",
    )


def pair_up(clips: list[int], truth: list[str], rng: np.random.Generator) -> list[tuple[int, int]]:
    """Shuffled clips in pairs of different labels: each in turn with the next unpaired clip of
    another label (a tail of one label stays unpaired)."""
    rest = [int(i) for i in rng.permutation(clips)]
    pairs: list[tuple[int, int]] = []
    while rest:
        a = rest.pop(0)
        b = next((i for i in rest if truth[i] != truth[a]), None)
        if b is None:
            break
        rest.remove(b)
        pairs.append((a, b))
    return pairs


def bench_joined(args: argparse.Namespace) -> dict[str, Any]:
    items = files(["2"])
    truth = [lab for _, lab in items]
    lib, _ = load(items, set())
    spec = AnnotatedDatabaseSpec(clips=[{"bvh": Path(f).name} for f, _ in items], **args.spec)
    near = int(round(lib.fps))  # frames either side of a join counted as near it
    out: dict[str, Any] = {}
    n_pairs: list[int] = []
    for k in (int(x) for x in (args.ks or "3").split(",")):
        macros: list[float] = []
        acc_near: list[float] = []
        acc_far: list[float] = []
        for trial in range(args.trials):
            picked = pick_labelled(truth, k, np.random.default_rng(100 * k + trial))
            labelled = sorted(picked)
            held_out = [i for i in range(len(items)) if i not in picked]
            pairs = pair_up(held_out, truth, np.random.default_rng(10_000 + 100 * k + trial))
            n_pairs.append(len(pairs))
            motions = [lib.motions[i] for i in labelled]
            motions += [join(lib.motions[a], lib.motions[b]) for a, b in pairs]
            jlib = MotionLibrary(tuple(m.name for m in motions), tuple(motions), tuple(() for _ in motions))
            emb, _, _, _ = embed_library(jlib, spec)
            z = standardize(emb, SVM_DIMS)
            counts = [m.num_frames for m in motions]
            clip_of = np.repeat(np.arange(len(counts)), counts)
            labels: list[list[dict[str, Any]]] = [
                [{"label": truth[i], "start": 0, "end": lib.motions[i].num_frames, "value": 1}]
                for i in labelled
            ]
            labels += [[] for _ in pairs]
            prop = propagate_as_built(z, clip_of, counts, labels, spec, lib.fps)
            truth_f = np.concatenate(
                [np.repeat(truth[i], lib.motions[i].num_frames) for i in labelled]
                + [
                    np.repeat([truth[a], truth[b]], [lib.motions[a].num_frames, lib.motions[b].num_frames])
                    for a, b in pairs
                ]
            )
            held = clip_of >= len(labelled)
            f1 = f1_table(prop.vocab, prop.labels, truth_f, held)
            macros.append(float(np.mean(list(f1.values()))))
            on = prop.labels > 0
            truth_col = np.array([prop.vocab.index(t) for t in truth_f])
            right = on[np.arange(len(truth_f)), truth_col] & (on.sum(axis=1) == 1)
            near_join = np.zeros(len(truth_f), dtype=bool)
            ends = np.cumsum(counts)
            for n, (a, _) in enumerate(pairs):
                end = int(ends[len(labelled) + n])
                start = end - counts[len(labelled) + n]
                change = start + lib.motions[a].num_frames  # first frame of the second clip
                near_join[max(start, change - near) : min(end, change + near)] = True
            acc_near.append(float(right[held & near_join].mean()))
            acc_far.append(float(right[held & ~near_join].mean()))
        out[str(k)] = {
            "macro_f1": round(float(np.mean(macros)), 4),
            "accuracy_near_change": round(float(np.mean(acc_near)), 4),
            "accuracy_far_from_change": round(float(np.mean(acc_far)), 4),
        }
    return {
        "dataset": "bandai-namco dataset-2",
        "pairs": int(round(float(np.mean(n_pairs)))),
        "trials": args.trials,
        "by_labelled_clips": out,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--part", default="all", choices=["all", "build", "search", "propagation", "joined"])
    ap.add_argument("--datasets", default="1,2")
    ap.add_argument("--labelled", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--budget", type=float, default=5.0)
    ap.add_argument("--trials", type=int, default=2)
    ap.add_argument(
        "--ks", default=None, help="propagation / joined: labelled clips per label (default 1,2,3,4,5 / 3)"
    )
    ap.add_argument(
        "--spec",
        default="{}",
        help="database spec settings as a JSON object, e.g. '{\"context_s\": 0}' (default: the spec's)",
    )
    args = ap.parse_args()
    try:
        args.spec = json.loads(args.spec)
        AnnotatedDatabaseSpec(clips=[{"bvh": "x.bvh"}], **args.spec)
    except (json.JSONDecodeError, TypeError, ValueError) as exc:
        ap.error(f"--spec: {exc}")
    if not DATA.is_dir():
        print(json.dumps({"skipped": f"no data at {DATA}"}))
        return
    result: dict[str, Any] = {"bench": "annotations"}
    if args.part in ("all", "build", "search"):
        build, engine = bench_build(args)
        result["build"] = build
        if args.part in ("all", "search"):
            result["search"] = bench_search(engine, args)
    if args.part in ("all", "propagation"):
        result["propagation"] = bench_propagation(args)
    if args.part in ("all", "joined"):
        result["joined"] = bench_joined(args)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
