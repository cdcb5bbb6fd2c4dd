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
from motion.bvh import BvhLimits
from motion.errors import ReadWarning
from motion.io import parse_motion
from motion.motion import check_rate_and_units, checked_arrays
from motion.resample import resample
from motion.serialize import skeleton_from_arrays, skeleton_to_arrays
from motion.skeleton import Skeleton
from schemas.clips import ClipSource, labels_past_clip_end

from .container import read_only

Arrays = dict[str, npt.NDArray[Any]]


@dataclass(frozen=True, slots=True)
class ClipInput:
    """One clip to put in a library: its name, file bytes (BVH, or glTF with ``animation`` picking
    one of its animations), declared units and labels."""

    name: str
    data: bytes
    units: str | None = None
    labels: list[dict[str, Any]] = field(default_factory=list)
    animation: str | int | None = None


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
    clips: list[ClipInput],
    fps: float | None = None,
    limits: BvhLimits | None = None,
    warnings: list[ReadWarning] | None = None,
) -> MotionLibrary:
    """Parse, resample (to ``fps`` or the first clip's rate) and convert clips to metres.

    ``warnings``: when given, what each clip's file needed to be read (:func:`motion.io.parse_motion`)
    is appended to it, its ``source`` the clip's name. Raises :class:`MotionError` (naming the
    clip) for unreadable clips, duplicate names, differing hierarchies or label ranges past a
    clip's end.
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
            m = parse_motion(
                c.data,
                units=c.units,
                limits=limits,
                source=c.name,
                name=c.name,
                animation=c.animation,
                warnings=warnings,
            )
        except MotionError as exc:
            raise MotionError(f"clip {c.name!r}: {exc}") from None
        motions.append(m)
    rate = float(fps) if fps else motions[0].fps
    first = motions[0].skeleton
    out: list[Motion] = []
    for c, m in zip(clips, motions, strict=True):
        if not m.skeleton.same_structure(first):
            raise MotionError(
                f"clip {c.name!r} has a different joint hierarchy from {clips[0].name!r}; a database's clips "
                f"must share one skeleton: retarget it onto the skeleton of {clips[0].name!r} first (segue "
                f"retarget FILE_OF_{c.name} --to FILE_OF_{clips[0].name} --out NEW.bvh) and use the new file"
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


def with_mirrors(lib: MotionLibrary) -> MotionLibrary:
    """The library followed by the mirror image of each of its clips (:func:`motion.mirror.mirror`:
    reflected across the YZ plane, left and right exchanged, in the skeleton's own conventions,
    with the joint frames of :func:`motion.mirror.joint_frames` over all the clips), named
    ``<name> (mirror)``, with its source's labels, sides exchanged (:func:`motion.mirror.mirrored_labels`).
    Raises :class:`MotionError` when the skeleton's left/right joints are not symmetric or a
    mirror's name is taken."""
    from motion.mirror import joint_frames, mirror, mirrored_labels

    names = [n + MIRROR_SUFFIX for n in lib.names]
    taken = sorted(set(names) & set(lib.names))
    if taken:
        raise MotionError(f"cannot name the mirror images: clip names {', '.join(taken)} are taken")
    frames = joint_frames(lib.motions)  # one convention for every image (they are cut together)
    mirrored = tuple(replace(mirror(m, frames), name=n) for m, n in zip(lib.motions, names, strict=True))
    labels = tuple(mirrored_labels(lb) for lb in lib.labels)
    return MotionLibrary(lib.names + tuple(names), lib.motions + mirrored, lib.labels + labels)


def speed_suffix(speed: float) -> str:
    """Appended to a clip's name to name its copy played at ``speed`` (:func:`with_speeds`): `` (x0.9)``."""
    return f" (x{speed:g})"


def time_scaled_labels(
    labels: Sequence[Mapping[str, Any]], speed: float, frames: int
) -> tuple[dict[str, Any], ...]:
    """A clip's label ranges as its copy played at ``speed`` carries them: source frame ``f`` is
    the copy's frame ``f / speed``, so ``[start, end)`` becomes ``[floor(start / speed),
    ceil(end / speed))``, clipped to the copy's ``frames`` frames (never empty)."""
    out = []
    for lb in labels:
        end = min(int(np.ceil(int(lb["end"]) / speed - 1e-9)), frames)
        start = min(int(np.floor(int(lb["start"]) / speed + 1e-9)), end - 1)
        out.append({**lb, "start": start, "end": end})
    return tuple(out)


def with_speeds(lib: MotionLibrary, speeds: Sequence[float]) -> MotionLibrary:
    """The library followed, for each of ``speeds`` in turn, by a copy of each of its clips played
    at that speed (``0.9``: 10 % slower, 1/0.9 as many frames) and resampled to the library's rate
    (:func:`motion.resample.resample`), named ``<name> (x0.9)`` (:func:`speed_suffix`), with its
    source's labels on the copy's frames (:func:`time_scaled_labels`). Applied after
    :func:`with_mirrors`, every mirror image has its copies too. Raises :class:`MotionError` when
    a copy's name is taken."""
    if not speeds:
        return lib
    names, motions, labels = list(lib.names), list(lib.motions), list(lib.labels)
    for speed in speeds:
        copies = [n + speed_suffix(speed) for n in lib.names]
        taken = sorted(set(copies) & set(names))
        if taken:
            raise MotionError(f"cannot name the copies at x{speed:g}: names {', '.join(taken)} are taken")
        for m, name, lb in zip(lib.motions, copies, lib.labels, strict=True):
            copy = replace(resample(replace(m, fps=m.fps * speed), m.fps), name=name)
            names.append(name)
            motions.append(copy)
            labels.append(time_scaled_labels(lb, speed, copy.num_frames))
    return MotionLibrary(tuple(names), tuple(motions), tuple(labels))


def speeds_frames(frames: int, speeds: Sequence[float]) -> int:
    """Frames of a library of ``frames`` frames with its copies at ``speeds`` (:func:`with_speeds`):
    ``frames / speed`` more per speed, rounded up (each copy's count is within a frame of it)."""
    return frames + sum(int(np.ceil(frames / s - 1e-9)) for s in speeds)


def clip_sources(clips: int, repeats: int, stored: int) -> list[int | None]:
    """For each of a library's ``stored`` clips, the index of the spec's clip (of ``clips``) it is or
    was made from, for a library laid out as :func:`with_mirrors` and :func:`with_speeds` lay it
    out: the clips, then ``repeats - 1`` whole repeats of clips derived from them in the same order
    (mirror images, then copies speed by speed), so clip ``i`` comes from ``i % clips``. A library
    of any other size (not laid out so) has the spec's clips first and ``None`` (no source) after."""
    if clips > 0 and stored == clips * repeats:
        return [i % clips for i in range(stored)]
    return [i if i < clips else None for i in range(stored)]


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


class StoredMotion(Motion):
    """A clip read from a database whose rotations and joint translations are stored narrower than
    float64 (a graph database stores them as float32: :func:`engines.graph.model.compact_motion`).

    It keeps them as stored, normally read-only views of the database's memory-mapped arrays
    (pages every engine process on the host shares), and widens them to float64 on every access
    of :attr:`rotations` / :attr:`joint_translations`: a copy of the clip's arrays per access, the
    same float64 numbers a :class:`~motion.Motion` widened at load would hold, without a private
    float64 copy of the library in each process (12 bytes a joint-frame). Everything else is a
    :class:`~motion.Motion`; :func:`dataclasses.replace` gives a ``StoredMotion`` holding the
    (float64) arrays it was given."""

    _stored_rotations: npt.NDArray[Any]
    _stored_joint_translations: npt.NDArray[Any]

    def __init__(
        self,
        skeleton: Skeleton,
        root_positions: npt.NDArray[Any],
        rotations: npt.NDArray[Any],
        fps: float,
        joint_translations: npt.NDArray[Any] | None = None,
        units: str = "unknown",
        name: str = "",
    ) -> None:
        rp = np.asarray(root_positions, dtype=np.float64)
        q = np.asarray(rotations)
        jt = np.zeros((0, 0, 3)) if joint_translations is None else np.asarray(joint_translations)
        jt = checked_arrays(skeleton, rp, q, jt)
        check_rate_and_units(fps, units)
        for key, value in (
            ("skeleton", skeleton),
            ("root_positions", rp),
            ("_stored_rotations", q),
            ("fps", float(fps)),
            ("_stored_joint_translations", jt),
            ("units", units),
            ("name", name),
        ):
            object.__setattr__(self, key, value)

    @property
    def rotations(self) -> npt.NDArray[np.float64]:
        """``(F, J, 4)`` local joint rotations, widened to float64 (a new array each access)."""
        return np.asarray(self._stored_rotations, dtype=np.float64)

    @property
    def joint_translations(self) -> npt.NDArray[np.float64]:
        """``(F, K, 3)`` animated joint translations, widened to float64 (a new array each access)."""
        return np.asarray(self._stored_joint_translations, dtype=np.float64)

    @property
    def stored_arrays(self) -> tuple[npt.NDArray[Any], npt.NDArray[Any]]:
        """The rotations and joint translations as stored (not widened, not to be written)."""
        return self._stored_rotations, self._stored_joint_translations


def library_from_arrays(arrays: Any) -> MotionLibrary:
    """Inverse of :func:`library_to_arrays`, over the stored arrays without copying them: each clip
    is a read-only view of its rows; float32 rotations and joint translations stay float32
    (:class:`StoredMotion`, widened where they are read)."""
    base = skeleton_from_arrays(arrays, "library.skeleton.")
    names = tuple(str(n) for n in arrays["library.names"])
    counts = np.asarray(arrays["library.frame_counts"])
    ends = np.cumsum(counts)
    fps = float(arrays["library.fps"])
    rp, q = read_only(arrays["library.root_positions"]), read_only(arrays["library.rotations"])
    jt = read_only(arrays["library.joint_translations"])
    offsets, es = np.asarray(arrays["library.offsets"]), np.asarray(arrays["library.end_site_offsets"])
    kind = Motion if q.dtype == np.float64 and jt.dtype == np.float64 else StoredMotion
    motions: list[Motion] = []
    for i, name in enumerate(names):
        s = slice(int(ends[i] - counts[i]), int(ends[i]))
        sk = replace(base, offsets=offsets[i], end_site_offsets=es[i])
        motions.append(kind(sk, rp[s], q[s], fps, jt[s], "m", name))
    labels = tuple(tuple(lb) for lb in json.loads(str(arrays["library.labels"])))
    return MotionLibrary(names, tuple(motions), labels)
