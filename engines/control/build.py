"""Building a control database (Hsu et al. 2004, Sec. 3 and 4.4 "Clustering").

The example pairs are cut into *instances* (synchronized control/target segments) by motion beats,
footplants, a fixed length or explicit markers; redundant instances are removed by complete-linkage
clustering of their control segments (Eq. 1 distance, scipy ``linkage(..., "complete")`` +
``fcluster``), one representative kept per cluster, chosen at random (seeded). Every frame of every
pair is stored as point clouds at the database rate, with the target's foot contacts and, for pairs
of two skeletons, a handhold flag (the partners' hands closer than ``handhold_m``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.cluster.hierarchy import fcluster, linkage

from motion import Motion, MotionError
from motion.contacts import detect_contacts
from schemas.control import ControlDatabaseSpec

from ..base import Arrays, EngineError, ShouldStop
from ..library import MotionLibrary
from .points import default_joints, derived_control, joint_cloud, sample_cloud

Array = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

PREFIX = "control."


@dataclass(frozen=True, slots=True)
class ControlDatabase:
    """The control-specific part of a database (all at the database rate ``fps``).

    Attributes
    ----------
    pairs: per pair ``(control clip name or None, target clip name)``.
    offsets: ``(n_pairs + 1,)`` first frame of each pair in the concatenated arrays.
    control: ``(F, Pc, 3)`` metres, control clouds of every pair end to end.
    target: ``(F, Pt, 3)`` metres, target clouds.
    instances: ``(N, 3)`` ``[pair, start, length]`` frames (start relative to the pair; the segment
        covers ``[start, start + length)`` and its end point ``start + length`` exists).
    representative: ``(N,)`` the kept instance standing for each instance (itself when kept).
    contacts: ``(F, K)`` target foot contacts; ``contact_joints`` their names.
    handhold: ``(F,)`` 1 holding hands, 0 not, -1 unknown (no control skeleton).
    meta: settings (joints, derived control separation, segmentation...).
    """

    fps: float
    pairs: tuple[tuple[str | None, str], ...]
    offsets: IntArray
    control: Array
    target: Array
    instances: IntArray
    representative: IntArray
    contacts: npt.NDArray[np.bool_]
    contact_joints: tuple[str, ...]
    handhold: npt.NDArray[np.int8]
    meta: dict[str, Any]

    @property
    def kept(self) -> IntArray:
        """Indices of the instances the search uses."""
        return np.flatnonzero(self.representative == np.arange(self.instances.shape[0]))

    @property
    def derived(self) -> bool:
        """True when the controls are derived from the targets' hips (walk databases)."""
        return bool(self.meta.get("derived", False))

    def to_arrays(self) -> Arrays:
        return {
            PREFIX + "meta": np.array(
                json.dumps(
                    {
                        **self.meta,
                        "fps": self.fps,
                        "pairs": [list(p) for p in self.pairs],
                        "contact_joints": list(self.contact_joints),
                    }
                )
            ),
            PREFIX + "offsets": self.offsets.astype(np.int64),
            PREFIX + "control": self.control.astype(np.float32),
            PREFIX + "target": self.target.astype(np.float32),
            PREFIX + "instances": self.instances.astype(np.int64),
            PREFIX + "representative": self.representative.astype(np.int64),
            PREFIX + "contacts": self.contacts,
            PREFIX + "handhold": self.handhold,
        }

    @classmethod
    def from_arrays(cls, arrays: Any) -> ControlDatabase:
        try:
            meta = json.loads(str(arrays[PREFIX + "meta"]))
        except KeyError:
            raise EngineError("this database has no control data; build it with kind 'control'") from None
        pairs = tuple((p[0], p[1]) for p in meta.pop("pairs"))
        contact_joints = tuple(meta.pop("contact_joints"))
        fps = float(meta.pop("fps"))
        return cls(
            fps=fps,
            pairs=pairs,
            offsets=np.asarray(arrays[PREFIX + "offsets"], dtype=np.intp),
            control=np.asarray(arrays[PREFIX + "control"], dtype=np.float64),
            target=np.asarray(arrays[PREFIX + "target"], dtype=np.float64),
            instances=np.asarray(arrays[PREFIX + "instances"], dtype=np.intp),
            representative=np.asarray(arrays[PREFIX + "representative"], dtype=np.intp),
            contacts=np.asarray(arrays[PREFIX + "contacts"], dtype=bool),
            contact_joints=contact_joints,
            handhold=np.asarray(arrays[PREFIX + "handhold"], dtype=np.int8),
            meta=meta,
        )


# ----------------------------------------------------------------------------------- segmentation


def segment_boundaries(
    method: str,
    *,
    control: Motion | None,
    target: Motion,
    seg: Any,
    markers_s: list[float],
    tempo_bpm: tuple[float, float] | None = None,
) -> tuple[IntArray, int]:
    """Unit boundaries (frames at the motions' rate, increasing) and how many units make a segment.

    ``tempo_bpm`` overrides the segmentation's tempo prior for beats (see :func:`consensus_tempo`)."""
    n = target.num_frames
    fps = target.fps
    if method == "fixed":
        step = max(1, int(round(seg.seconds * fps)))
        return np.arange(0, n, step, dtype=np.intp), 1
    if method == "markers":
        b = np.unique(np.round(np.asarray(markers_s) * fps).astype(np.intp))
        return b[(b >= 0) & (b < n)], 1
    if method == "beats":
        from motion.beats import detect_beats

        source = control if control is not None and seg.beats_source == "control" else target
        try:
            beats = detect_beats(source, tempo_bpm=tempo_bpm or tuple(seg.tempo_bpm))
        except MotionError as exc:
            raise EngineError(f"beat detection failed on {source.name!r}: {exc}") from None
        times = np.asarray(beats.times_s, dtype=np.float64)
        expected = source.duration_s / beats.period_s if beats.period_s > 0 else 0.0
        if times.size < 0.5 * expected:
            # too few beats estimated: fall back on the reference grid (phase + k period)
            times = np.arange(beats.phase_s % beats.period_s, source.duration_s, beats.period_s)
        b = np.unique(np.round(times * fps).astype(np.intp))
        return b[(b >= 0) & (b < n)], int(seg.beats_per_segment)
    if method == "footplants":
        _, flags = detect_contacts(target)
        onsets = np.flatnonzero((flags[1:] & ~flags[:-1]).any(axis=1)) + 1
        # one boundary per footplant: merge onsets of joints of the same foot (ankle + toe) closer
        # than a fifth of a second
        if onsets.size:
            keep = np.concatenate(([True], np.diff(onsets) > 0.2 * fps))
            onsets = onsets[keep]
        return onsets.astype(np.intp), int(seg.steps_per_segment)
    raise EngineError(f"unknown segmentation method {method!r}")


def instances_from_boundaries(
    bounds: IntArray, units: int, n_frames: int, fps: float, min_s: float, max_s: float, overlap: bool
) -> IntArray:
    """``(M, 2)`` ``[start, length]`` segments spanning ``units`` consecutive unit boundaries, starting
    at every ``units``-th boundary (every boundary with ``overlap``), inside ``[0, n_frames - 1]`` and
    ``[min_s, max_s]`` seconds long."""
    b = bounds[(bounds >= 0) & (bounds <= n_frames - 1)]
    if b.size <= units:
        return np.zeros((0, 2), dtype=np.intp)
    starts = np.arange(0, b.size - units, 1 if overlap else units)
    s, e = b[starts], b[starts + units]
    length = e - s
    ok = (length >= max(1, min_s * fps)) & (length <= max_s * fps)
    return np.stack((s[ok], length[ok]), axis=-1).astype(np.intp)


def consensus_tempo(
    motions: list[Motion], prior: tuple[float, float], tolerance: float = 0.12
) -> tuple[float, float]:
    """A narrow tempo prior shared by all the example pairs: the median of the tempos detected in
    every motion (both partners hear the same music), each folded by octaves (x2, /2) towards the
    median, +- ``tolerance``. Beat detection on real dances often locks on half or double the
    tempo of a single clip; a consistent segmentation needs one tempo for the whole database."""
    from motion.beats import detect_beats

    bpms = []
    for m in motions:
        try:
            bpms.append(detect_beats(m, tempo_bpm=prior).bpm)
        except MotionError:
            continue
    if not bpms:
        return prior
    ref = float(np.median(bpms))
    folded = [b * 2.0 ** np.round(np.log2(ref / b)) for b in bpms]
    centre = float(np.median(folded))
    return (centre * (1 - tolerance), centre * (1 + tolerance))


# ------------------------------------------------------------------------------------- clustering


def segment_distance_matrix(clouds: Array) -> Array:
    """Condensed ``(N (N - 1) / 2,)`` RMS point distances (metres) between segments ``(N, L, P, 3)``
    after the optimal rotation about +Y and floor translation (Eq. 1, symmetric for equal lengths)."""
    n, length, p, _ = clouds.shape
    flat = clouds.reshape(n, length * p, 3)
    cen = flat - flat.mean(axis=1, keepdims=True) * np.array([1.0, 0.0, 1.0])
    xz = cen[..., [0, 2]]
    y = cen[..., 1]
    sq = (xz**2).sum(axis=(1, 2))
    ysq = (y**2).sum(axis=1)
    i, j = np.triu_indices(n, 1)
    out = np.empty(i.size)
    chunk = 4096
    for a in range(0, i.size, chunk):
        ii, jj = i[a : a + chunk], j[a : a + chunk]
        xi, xj = xz[ii], xz[jj]
        c = (xi * xj).sum(axis=(1, 2))
        s = (xi[..., 1] * xj[..., 0] - xi[..., 0] * xj[..., 1]).sum(axis=1)
        planar = sq[ii] + sq[jj] - 2 * np.hypot(c, s)
        vert = ysq[ii] + ysq[jj] - 2 * (y[ii] * y[jj]).sum(axis=1)
        # the mean heights differ too: add back what centring removed from y
        my = flat[ii, :, 1].mean(axis=1) - flat[jj, :, 1].mean(axis=1)
        out[a : a + chunk] = np.sqrt(np.maximum(planar + vert, 0.0) / (length * p) + my**2)
    return out


def cluster_instances(clouds: Array, threshold_m: float, seed: int) -> IntArray:
    """``(N,)`` the representative of each segment after complete-linkage clustering with distance
    threshold ``threshold_m`` (one random member per cluster, seeded); identity when the threshold is 0."""
    n = clouds.shape[0]
    if threshold_m <= 0 or n < 2:
        return np.arange(n, dtype=np.intp)
    z = linkage(segment_distance_matrix(clouds), method="complete")
    labels = fcluster(z, t=threshold_m, criterion="distance")
    rng = np.random.default_rng(seed)
    rep = np.empty(n, dtype=np.intp)
    for lab in np.unique(labels):
        members = np.flatnonzero(labels == lab)
        rep[members] = members[rng.integers(members.size)]
    return rep


# ------------------------------------------------------------------------------------------ build


def _hands(names: list[str]) -> list[str]:
    return [n for n in names if "hand" in n.lower() or "wrist" in n.lower()]


def build_control_database(
    spec: ControlDatabaseSpec, library: MotionLibrary, should_stop: ShouldStop
) -> ControlDatabase:
    """Segment, cluster and store the example pairs of a :class:`schemas.control.ControlDatabaseSpec`:
    every pair's control and target clouds, contacts and hand hold (:func:`_example_pair`), its
    instances (segments) from the spec's segmentation, then the instances clustered on their
    control segments (:func:`cluster_instances`)."""
    seg = spec.segmentation
    first = library.clip(spec.pairs[0].target).skeleton
    tjoints = list(spec.target_joints) if spec.target_joints else default_joints(first)
    derived = any(p.control is None for p in spec.pairs)
    if derived and any(p.control is not None for p in spec.pairs):
        raise EngineError("either every pair has a control clip or none does (derived walk controls)")
    cjoints: list[str] = []
    first_control = spec.pairs[0].control
    if first_control is not None:
        cskel = library.clip(first_control).skeleton
        # the control cloud leaves the feet out by default: a leader's steps say little about where
        # the follower stands, and on the CMU salsa couples they add noise to the alignment (mean
        # leave-one-out error 0.172 x height without them, 0.186 with them)
        cjoints = list(spec.control_joints) if spec.control_joints else default_joints(cskel, feet=False)
    tempo: tuple[float, float] | None = None
    if seg.method == "beats":
        everyone = [library.clip(p.target) for p in spec.pairs]
        everyone += [library.clip(p.control) for p in spec.pairs if p.control is not None]
        tempo = consensus_tempo(everyone, (seg.tempo_bpm[0], seg.tempo_bpm[1]))
    examples: list[_ExamplePair] = []
    for k, pair in enumerate(spec.pairs):
        if should_stop():
            raise InterruptedError
        example = _example_pair(spec, library, k, pair, tjoints, cjoints, tempo)
        if examples and example.contact_names != examples[0].contact_names:
            raise EngineError("the targets' foot joints differ between pairs")
        examples.append(example)
    instances = (
        np.concatenate([e.instances for e in examples]) if examples else np.zeros((0, 3), dtype=np.intp)
    )
    if instances.shape[0] == 0:
        raise EngineError(
            f"segmentation {seg.method!r} found no segments between {seg.min_segment_s} and "
            f"{seg.max_segment_s} s; check the clips or choose another method"
        )
    control = np.concatenate([e.control for e in examples])
    off = np.concatenate(([0], np.cumsum([e.frames for e in examples]))).astype(np.intp)
    rep = cluster_instances(_segment_clouds(control, off, instances), spec.cluster_threshold_m, spec.seed)
    return ControlDatabase(
        fps=library.fps,
        pairs=tuple((p.control, p.target) for p in spec.pairs),
        offsets=off,
        control=control,
        target=np.concatenate([e.target for e in examples]),
        instances=instances.astype(np.intp),
        representative=rep,
        contacts=np.concatenate([e.contacts for e in examples]),
        contact_joints=examples[0].contact_names,
        handhold=np.concatenate([e.handhold for e in examples]),
        meta={
            "derived": derived,
            "control_joints": cjoints,
            "target_joints": tjoints,
            "hip_separation_m": spec.hip_separation_m,
            "handhold_m": spec.handhold_m,
            "segmentation": seg.model_dump(mode="json"),
            "tempo_bpm": None if tempo is None else [float(tempo[0]), float(tempo[1])],
        },
    )


@dataclass(slots=True)
class _ExamplePair:
    """One (control, target) example pair, cut to its common length ``frames``."""

    frames: int
    control: Array  # (F, Pc, 3) control cloud, metres
    target: Array  # (F, Pt, 3) target cloud, metres
    contacts: npt.NDArray[np.bool_]  # (F, K) the target's foot contacts
    contact_names: tuple[str, ...]  # the K foot joints
    handhold: npt.NDArray[np.int8]  # (F,) 1 hands joined, 0 apart, -1 unknown
    instances: IntArray  # (S, 3) pair, start frame, length of each segment


def _example_pair(
    spec: ControlDatabaseSpec,
    library: MotionLibrary,
    k: int,
    pair: Any,
    tjoints: list[str],
    cjoints: list[str],
    tempo: tuple[float, float] | None,
) -> _ExamplePair:
    """Pair ``k``'s clouds (a walk's control is derived from its target's hips), contacts, hand
    hold and segments."""
    seg = spec.segmentation
    tm = library.clip(pair.target)
    cm = library.clip(pair.control) if pair.control is not None else None
    n = tm.num_frames if cm is None else min(tm.num_frames, cm.num_frames)
    tm = tm.slice(0, n)
    tpos = tm.global_positions()
    tcloud = joint_cloud(tm, tjoints, f"target {pair.target!r}", tpos)
    if cm is None:
        ccloud = derived_control(tm, spec.hip_separation_m, tpos)
        hold = np.full(n, -1, dtype=np.int8)
    else:
        cm = cm.slice(0, n)
        cpos = cm.global_positions()
        ccloud = joint_cloud(cm, cjoints, f"control {pair.control!r}", cpos)
        hold = _handhold(cm, tm, cpos, tpos, spec.handhold_m)
    joints, flags = detect_contacts(tm, positions=tpos)
    bounds, units = segment_boundaries(
        seg.method, control=cm, target=tm, seg=seg, markers_s=list(pair.markers_s), tempo_bpm=tempo
    )
    rows = instances_from_boundaries(
        bounds, units, n, library.fps, seg.min_segment_s, seg.max_segment_s, seg.overlap
    )
    return _ExamplePair(
        frames=n,
        control=ccloud,
        target=tcloud,
        contacts=flags,
        contact_names=tuple(tm.skeleton.names[j] for j in joints),
        handhold=hold,
        instances=np.column_stack((np.full(rows.shape[0], k, dtype=np.intp), rows)),
    )


def _handhold(cm: Motion, tm: Motion, cpos: Array, tpos: Array, within_m: float) -> npt.NDArray[np.int8]:
    """``(F,)`` 1 where a hand of the control is within ``within_m`` of a hand of the target, 0
    where not, -1 throughout when either skeleton has no hand joints."""
    n = tm.num_frames
    ch = [h for h in _hands(list(cm.skeleton.names)) if h in default_joints(cm.skeleton)]
    th = [h for h in _hands(list(tm.skeleton.names)) if h in default_joints(tm.skeleton)]
    if not (ch and th):
        return np.full(n, -1, dtype=np.int8)
    a = joint_cloud(cm, ch, "control hands", cpos)
    b = joint_cloud(tm, th, "target hands", tpos)
    dist = np.linalg.norm(a[:, :, None] - b[:, None, :], axis=-1).min(axis=(1, 2))
    return np.asarray(dist < within_m, dtype=np.int8)


def _segment_clouds(control: Array, offsets: IntArray, instances: IntArray, length: int = 8) -> Array:
    """``(S, length, P, 3)`` each instance's control segment resampled to a common length (what
    Eq. 1 compares when clustering)."""
    pos = (
        offsets[instances[:, 0], None]
        + instances[:, 1, None]
        + instances[:, 2, None] * np.linspace(0, 1, length)
    )
    return sample_cloud(control, pos)
