"""The motion library: the common part of every database.

The clips of a spec, parsed, resampled to one frame rate and converted to metres, stored as a few
concatenated arrays (one npz, no pickle). Clips must share one joint hierarchy (names and parents);
offsets may differ per clip (different performers).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from motion import Motion, MotionError
from motion.bvh import BvhLimits, parse_bvh
from motion.resample import resample
from motion.serialize import skeleton_from_arrays, skeleton_to_arrays
from schemas.clips import ClipSource, labels_past_clip_end

Arrays = dict[str, npt.NDArray[Any]]


@dataclass(frozen=True, slots=True)
class ClipInput:
    """One clip to put in a library: its name, BVH bytes, declared units and labels."""

    name: str
    data: bytes
    units: str | None = None
    labels: list[dict[str, Any]] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class MotionLibrary:
    """Clips at one rate, in metres, sharing one hierarchy."""

    names: tuple[str, ...]
    motions: tuple[Motion, ...]
    labels: tuple[tuple[dict[str, Any], ...], ...]

    @property
    def fps(self) -> float:
        return self.motions[0].fps

    @property
    def total_frames(self) -> int:
        return sum(m.num_frames for m in self.motions)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise MotionError(
                f"no clip named {name!r} in the database; clips: {', '.join(self.names)}"
            ) from None

    def clip(self, name: str) -> Motion:
        return self.motions[self.index(name)]


def build_library(
    clips: list[ClipInput], fps: float | None = None, limits: BvhLimits | None = None
) -> MotionLibrary:
    """Parse, resample (to ``fps`` or the first clip's rate) and convert clips to metres.

    Raises :class:`MotionError` (naming the clip) for unreadable clips, duplicate names, differing
    hierarchies or label ranges past a clip's end.
    """
    if not clips:
        raise MotionError("a database needs at least one clip")
    names = [c.name for c in clips]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise MotionError(f"clip names must be unique; repeated: {', '.join(dup)} (give them a 'name')")
    motions: list[Motion] = []
    for c in clips:
        try:
            m = parse_bvh(c.data, units=c.units, limits=limits, source=c.name, name=c.name)
        except MotionError as exc:
            raise MotionError(f"clip {c.name!r}: {exc}") from None
        motions.append(m)
    rate = float(fps) if fps else motions[0].fps
    first = motions[0].skeleton
    out: list[Motion] = []
    for c, m in zip(clips, motions, strict=True):
        if not m.skeleton.same_structure(first):
            raise MotionError(
                f"clip {c.name!r} has a different joint hierarchy from {clips[0].name!r}; "
                "a database's clips must share one skeleton"
            )
        m = resample(m.to_units("m") if m.units != "unknown" else m.with_units("m"), rate)
        out.append(replace(m, name=c.name))
    sources = [ClipSource.model_validate({"bvh": c.name, "name": c.name, "labels": c.labels}) for c in clips]
    past_end = labels_past_clip_end(sources, [m.num_frames for m in out], rate)
    if past_end:
        raise MotionError("; ".join(past_end))
    return MotionLibrary(tuple(names), tuple(out), tuple(tuple(c.labels) for c in clips))


MIRROR_SUFFIX = " (mirror)"
"""Appended to a clip's name to name its mirror image (:func:`with_mirrors`)."""


def mirrored_labels(labels: Sequence[Mapping[str, Any]]) -> tuple[dict[str, Any], ...]:
    """A clip's label ranges as its mirror image carries them: the same frames and values, each
    label's named side exchanged (:func:`motion.mirror.mirror_label`: ``wave-left-hand`` ->
    ``wave-right-hand``; ``walk`` stays ``walk``)."""
    from motion.mirror import mirror_label

    return tuple({**lb, "label": mirror_label(str(lb["label"]))} for lb in labels)


def with_mirrors(lib: MotionLibrary) -> MotionLibrary:
    """The library followed by the mirror image of each of its clips (:func:`motion.mirror.mirror`:
    reflected across the YZ plane, left and right exchanged), named ``<name> (mirror)``, with its
    source's labels, sides exchanged (:func:`mirrored_labels`). Raises :class:`MotionError` when
    the skeleton's left/right joints are not symmetric or a mirror's name is taken."""
    from motion.mirror import mirror

    names = [n + MIRROR_SUFFIX for n in lib.names]
    taken = sorted(set(names) & set(lib.names))
    if taken:
        raise MotionError(f"cannot name the mirror images: clip names {', '.join(taken)} are taken")
    mirrored = tuple(replace(mirror(m), name=n) for m, n in zip(lib.motions, names, strict=True))
    labels = tuple(mirrored_labels(lb) for lb in lib.labels)
    return MotionLibrary(lib.names + tuple(names), lib.motions + mirrored, lib.labels + labels)


def library_to_arrays(lib: MotionLibrary) -> Arrays:
    """Concatenated arrays of a library (frames of all clips end to end)."""
    counts = np.array([m.num_frames for m in lib.motions], dtype=np.int64)
    arrays: Arrays = {
        "library.names": np.array(lib.names, dtype=str),
        "library.frame_counts": counts,
        "library.fps": np.array(lib.fps, dtype=np.float64),
        "library.labels": np.array(json.dumps([list(lb) for lb in lib.labels])),
        "library.root_positions": np.concatenate([m.root_positions for m in lib.motions]),
        "library.rotations": np.concatenate([np.ascontiguousarray(m.rotations) for m in lib.motions]),
        "library.joint_translations": np.concatenate([m.joint_translations for m in lib.motions]),
        "library.offsets": np.stack([m.skeleton.offsets for m in lib.motions]),
        "library.end_site_offsets": np.stack([m.skeleton.end_site_offsets for m in lib.motions]),
    }
    arrays.update(skeleton_to_arrays(lib.motions[0].skeleton, "library.skeleton."))
    return arrays


def library_from_arrays(arrays: Any) -> MotionLibrary:
    """Inverse of :func:`library_to_arrays`."""
    base = skeleton_from_arrays(arrays, "library.skeleton.")
    names = tuple(str(n) for n in arrays["library.names"])
    counts = np.asarray(arrays["library.frame_counts"])
    ends = np.cumsum(counts)
    fps = float(arrays["library.fps"])
    rp, q = np.asarray(arrays["library.root_positions"]), np.asarray(arrays["library.rotations"])
    jt = np.asarray(arrays["library.joint_translations"])
    offsets, es = np.asarray(arrays["library.offsets"]), np.asarray(arrays["library.end_site_offsets"])
    motions = []
    for i, name in enumerate(names):
        s = slice(int(ends[i] - counts[i]), int(ends[i]))
        sk = replace(base, offsets=offsets[i], end_site_offsets=es[i])
        motions.append(Motion(sk, rp[s], q[s], fps, jt[s], "m", name))
    labels = tuple(tuple(lb) for lb in json.loads(str(arrays["library.labels"])))
    return MotionLibrary(names, tuple(motions), labels)
