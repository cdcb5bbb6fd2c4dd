"""A small motion graph built by hand (no build half needed): synthetic walking clips on straight
lines and arcs, leaf edges between frames of the same gait phase, a balanced two-level-or-more
edge hierarchy per clip pair, and root tracks from :func:`motion.ground.ground_frames`."""

from __future__ import annotations

from typing import Any

import numpy as np

from engines.graph.model import EdgeTree, RootTracks
from engines.library import MotionLibrary
from motion import Motion
from motion import rotations as rot
from motion.ground import ground_frames
from tests.motion.synthetic import BIPED_NAMES, biped_skeleton

PERIOD = 30  # frames per gait cycle at 30 fps (1 Hz leg swing)


def arc_biped(frames: int, speed: float, turn_deg_s: float, seed: int = 0, fps: float = 30.0) -> Motion:
    """A biped walking at ``speed`` m/s while its heading turns at ``turn_deg_s`` (0 = straight)."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    yaw = np.radians(turn_deg_s) * t
    step = speed / fps * np.stack((np.sin(yaw), np.cos(yaw)), axis=-1)
    xz = np.cumsum(step, axis=0) - step[0]
    root = np.stack((xz[:, 0], 0.9 + 0.02 * np.sin(4 * np.pi * t), xz[:, 1]), axis=-1)
    q = rot.identity((frames, len(BIPED_NAMES)))
    q[:, 0] = rot.from_yaw(yaw)
    swing = 0.4 * np.sin(2 * np.pi * t)
    x_axis = np.array([1.0, 0.0, 0.0])
    q[:, 1] = rot.from_axis_angle(x_axis, swing)
    q[:, 4] = rot.from_axis_angle(x_axis, -swing)
    q[:, 2] = rot.from_axis_angle(x_axis, 0.3 + 0.3 * np.sin(2 * np.pi * t + 1))
    q[:, 5] = rot.from_axis_angle(x_axis, 0.3 - 0.3 * np.sin(2 * np.pi * t + 1))
    q[:, 7:] = rot.multiply(q[:, 7:], rot.exp(rng.normal(scale=0.02, size=(frames, len(BIPED_NAMES) - 7, 3))))
    return Motion(biped_skeleton(), root, q, fps, units="m", name="arc")


CLIPS: tuple[tuple[str, float, float], ...] = (
    ("straight", 1.2, 0.0),
    ("slow", 0.8, 0.0),
    ("left", 1.0, 40.0),
    ("right", 1.0, -40.0),
)


def synthetic_library(frames: int = 150, labels: bool = True) -> MotionLibrary:
    motions = tuple(arc_biped(frames, v, turn, seed=i) for i, (_, v, turn) in enumerate(CLIPS))
    names = tuple(n for n, _, _ in CLIPS)
    lab: list[tuple[dict[str, Any], ...]] = [() for _ in CLIPS]
    if labels:
        lab[1] = ({"label": "slow", "start": 0, "end": frames, "value": 1},)
        lab[0] = ({"label": "slow", "start": 0, "end": frames, "value": -1},)
    return MotionLibrary(names, motions, tuple(lab))


def leaf_edges(
    library: MotionLibrary, stride: int = 7
) -> dict[tuple[int, int], list[tuple[int, int, float]]]:
    """Per ordered clip pair, leaves ``(from_frame, to_frame, cost)`` between frames whose next
    frame has the gait phase of the frame jumped to."""
    out: dict[tuple[int, int], list[tuple[int, int, float]]] = {}
    for a, ma in enumerate(library.motions):
        for b, mb in enumerate(library.motions):
            leaves = []
            for i in range(4, ma.num_frames - 5, stride):
                for j in range((i + 1) % PERIOD, mb.num_frames - 5, PERIOD):
                    if a == b and abs(j - (i + 1)) < 10:
                        continue
                    leaves.append((i, j, 0.1 + 0.2 * (a != b) + 0.001 * ((i + j) % 5)))
            out[(a, b)] = leaves
    return out


def build_tree(
    pairs: dict[tuple[int, int], list[tuple[int, int, float]]], roots_per_pair: int = 3
) -> EdgeTree:
    """Per clip pair: leaves sorted by (from, to) and split in ``roots_per_pair`` groups; each group
    is a balanced binary tree by recursive halving (internal nodes: rounded mean frames, mean cost)."""
    fc: list[int] = []
    ff: list[int] = []
    tc: list[int] = []
    tf: list[int] = []
    cost: list[float] = []
    parent: list[int] = []
    left: list[int] = []
    right: list[int] = []

    def node(a: int, b: int, f: int, t: int, c: float, lft: int = -1, rgt: int = -1) -> int:
        fc.append(a)
        ff.append(f)
        tc.append(b)
        tf.append(t)
        cost.append(c)
        parent.append(-1)
        left.append(lft)
        right.append(rgt)
        return len(fc) - 1

    def grow(a: int, b: int, group: list[tuple[int, int, float]]) -> tuple[int, list[int]]:
        if len(group) == 1:
            f, t, c = group[0]
            return node(a, b, f, t, c), [0]
        half = len(group) // 2
        lid, _ = grow(a, b, group[:half])
        rid, _ = grow(a, b, group[half:])
        f = int(np.floor(np.mean([g[0] for g in group]) + 0.5))
        t = int(np.floor(np.mean([g[1] for g in group]) + 0.5))
        me = node(a, b, f, t, float(np.mean([g[2] for g in group])), lid, rid)
        parent[lid] = parent[rid] = me
        return me, []

    for (a, b), leaves in sorted(pairs.items()):
        if not leaves:
            continue
        leaves = sorted(leaves)
        for group in np.array_split(np.arange(len(leaves)), min(roots_per_pair, len(leaves))):
            grow(a, b, [leaves[int(i)] for i in group])
    arr = lambda v: np.asarray(v, dtype=np.int64)  # noqa: E731
    return EdgeTree(arr(fc), arr(ff), arr(tc), arr(tf), np.asarray(cost), arr(parent), arr(left), arr(right))


def tracks_of(library: MotionLibrary) -> RootTracks:
    xz, yaw = [], []
    for m in library.motions:
        p, h = ground_frames(m)
        xz.append(p)
        yaw.append(np.unwrap(h))
    counts = [m.num_frames for m in library.motions]
    return RootTracks(
        np.concatenate(([0], np.cumsum(counts))).astype(np.int64), np.concatenate(xz), np.concatenate(yaw)
    )


def synthetic_graph(frames: int = 150) -> tuple[MotionLibrary, EdgeTree, RootTracks]:
    library = synthetic_library(frames)
    return library, build_tree(leaf_edges(library)), tracks_of(library)
