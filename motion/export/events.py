"""Timed events of a motion for game engines: foot contacts, music beats and labels.

An event is a plain JSON object (so it goes as is into a GLB animation's ``extras`` and into the
JSON frames export), times in seconds from the first frame:

* ``{"type": "contact", "joint": "lFoot", "time_s": 0.53, "duration_s": 0.31}``: a foot planted
  (:func:`contact_runs`, measured on the exported motion itself, debounced so that one plant is
  one event at any frame rate); with several characters, ``"character"`` names the one it
  belongs to;
* ``{"type": "beat", "index": 3, "time_s": 1.5}``: a music beat of a rhythm result;
* ``{"type": "label", "label": "walk", "time_s": 0.0, "duration_s": 5.0}``: a span of frames whose
  source frames carry the label (an annotation result's ``achieved_ranges``).

Events are sorted by time, then type. Times are in seconds, not frames, so that they stay right
when the motion is resampled to another frame rate for export.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..contacts import foot_joints
from ..errors import MotionError
from ..motion import Motion
from ..units import standing_height
from .characters import split_characters, without_prefix

Event = dict[str, Any]

EVENT_KINDS = ("contacts", "beats", "labels")
"""What ``events`` may ask for (CLI ``--events``, HTTP ``events=``)."""

# Foot plants, in body heights and seconds (so that a plant is one event at any frame rate)
PLANT_ENTER = (0.05, 0.35)
"""A plant starts where a foot is within 5 % of the body height of its floor and moves slower than
0.35 body heights per second horizontally (the quality report's contact thresholds)..."""
PLANT_STAY = (0.075, 0.6)
"""... and lasts while it stays within 7.5 % and under 0.6 body heights per second (hysteresis)."""
PLANT_SPEED_WINDOW_S = 0.1
"""Foot speed: the displacement over this span (centred), not frame to frame (mocap jitter)."""
PLANT_GAP_S = 0.12
"""Lifts shorter than this join the plants on either side."""
PLANT_MIN_S = 0.1
"""Plants shorter than this are dropped."""


def _runs(flags: np.ndarray[Any, np.dtype[np.bool_]]) -> list[tuple[int, int]]:
    """``[(start, end), ...]`` frame runs of True (end exclusive)."""
    x = np.concatenate(([0], flags.astype(np.int8), [0]))
    edges = np.flatnonzero(np.diff(x))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _planted(
    motion: Motion,
    positions: np.ndarray[Any, np.dtype[np.float64]],
    height: float,
    height_tol: float,
    speed_tol: float,
) -> np.ndarray[Any, np.dtype[np.bool_]]:
    """``(F, K)`` whether each foot (``positions (F, K, 3)``) is low and slow, in body heights
    (``height``, the motion's units)."""
    floor = np.percentile(positions[:, :, 1], 5, axis=0)
    low = positions[:, :, 1] - floor < height_tol * height
    f = positions.shape[0]
    half = max(1, int(round(PLANT_SPEED_WINDOW_S * motion.fps / 2)))
    i = np.arange(f)
    a, b = np.clip(i - half, 0, f - 1), np.clip(i + half, 0, f - 1)
    span = np.maximum(b - a, 1) / motion.fps
    speed = np.linalg.norm(positions[b][:, :, [0, 2]] - positions[a][:, :, [0, 2]], axis=-1) / span[:, None]
    return np.asarray(low & (speed < speed_tol * height))


def contact_runs(motion: Motion) -> list[tuple[int, int, int]]:
    """The foot plants of ``motion``: ``(joint, start frame, end frame exclusive)`` per plant, feet
    found by name (:func:`motion.contacts.foot_joints`; none: an empty list).

    Debounced so that their number does not depend on the frame rate: a plant starts where a
    foot meets :data:`PLANT_ENTER` and lasts while it meets :data:`PLANT_STAY` (hysteresis),
    speeds are measured over :data:`PLANT_SPEED_WINDOW_S`, lifts shorter than
    :data:`PLANT_GAP_S` are bridged and plants shorter than :data:`PLANT_MIN_S` dropped.
    """
    try:
        joints = foot_joints(motion.skeleton)
    except MotionError:
        return []
    pos = motion.global_positions()
    height = standing_height(pos)
    if motion.num_frames < 2 or height <= 0:
        return []
    feet = pos[:, joints]
    enter = _planted(motion, feet, height, *PLANT_ENTER)
    stay = _planted(motion, feet, height, *PLANT_STAY)
    out: list[tuple[int, int, int]] = []
    for k, j in enumerate(joints.tolist()):
        merged: list[tuple[int, int]] = []
        for a, b in _runs(stay[:, k]):
            if not enter[a:b, k].any():
                continue
            if merged and (a - merged[-1][1]) / motion.fps < PLANT_GAP_S:
                merged[-1] = (merged[-1][0], b)
            else:
                merged.append((a, b))
        out += [(j, a, b) for a, b in merged if (b - a) / motion.fps >= PLANT_MIN_S - 1e-9]
    return out


def contact_events(motion: Motion, character: str | None = None) -> list[Event]:
    """One ``contact`` event per foot plant of ``motion`` (:func:`contact_runs`).

    A motion without joints named like feet has no contacts (an empty list, not an error). The
    duration of a run of ``n`` frames is ``n / fps`` seconds (each frame stands for one period).
    """
    out: list[Event] = []
    names = motion.skeleton.names
    for j, a, b in contact_runs(motion):
        ev: Event = {
            "type": "contact",
            "joint": names[j],
            "time_s": round(a / motion.fps, 6),
            "duration_s": round((b - a) / motion.fps, 6),
        }
        if character is not None:
            ev["character"] = character
        out.append(ev)
    return out


def contact_events_of(motion: Motion) -> list[Event]:
    """:func:`contact_events` of every character of ``motion`` (each character of a combined
    motion, :func:`motion.export.characters.split_characters`, named by its prefix)."""
    chars = split_characters(motion)
    if chars is None:
        return contact_events(motion)
    out: list[Event] = []
    for c in chars:
        plain, pre = without_prefix(c)  # feet and sides are found by name
        out += [dict(ev, joint=pre + ev["joint"]) for ev in contact_events(plain, pre.rstrip("_"))]
    return out


def beat_events(times_s: Sequence[float], duration_s: float) -> list[Event]:
    """One ``beat`` event per music beat time within ``[0, duration_s]`` seconds."""
    return [
        {"type": "beat", "index": i, "time_s": round(float(t), 6)}
        for i, t in enumerate(times_s)
        if 0.0 <= float(t) <= duration_s + 1e-9
    ]


def label_events(ranges: Mapping[str, Sequence[Sequence[int]]], fps: float) -> list[Event]:
    """One ``label`` event per ``[start, end)`` frame range (at ``fps``) of each label."""
    return [
        {
            "type": "label",
            "label": str(label),
            "time_s": round(int(a) / fps, 6),
            "duration_s": round((int(b) - int(a)) / fps, 6),
        }
        for label, runs in ranges.items()
        for a, b in runs
    ]


def result_events(
    annotations: Mapping[str, Any], fps: float, duration_s: float, kinds: Sequence[str] = ("beats", "labels")
) -> list[Event]:
    """The ``beats`` (``annotations["music_beats_s"]``) and ``labels``
    (``annotations["achieved_ranges"]``, frames at the result's ``fps``) events a result's report
    carries; kinds the result does not have give nothing."""
    out: list[Event] = []
    if "beats" in kinds:
        out += beat_events(annotations.get("music_beats_s", []), duration_s)
    if "labels" in kinds:
        out += label_events(annotations.get("achieved_ranges", {}), fps)
    return out


def sorted_events(events: Sequence[Event]) -> list[Event]:
    """Events by time, then type (stable otherwise)."""
    return sorted(events, key=lambda e: (float(e["time_s"]), str(e["type"])))


def parse_kinds(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"contacts,beats"`` (or a list) -> ``("contacts", "beats")``; ``all`` means every kind.

    Raises :class:`MotionError` naming an unknown kind."""
    items = [s.strip() for s in (text.split(",") if isinstance(text, str) else text) if s.strip()]
    if items == ["all"]:
        return EVENT_KINDS
    bad = [s for s in items if s not in EVENT_KINDS]
    if bad:
        raise MotionError(f"unknown event kind {bad[0]!r}; use {', '.join(EVENT_KINDS)} or all")
    return tuple(dict.fromkeys(items))
