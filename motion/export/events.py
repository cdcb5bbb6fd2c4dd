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

from ..contacts import (  # noqa: F401  (the plant thresholds, re-exported)
    PLANT_ENTER,
    PLANT_GAP_S,
    PLANT_MIN_S,
    PLANT_SPEED_WINDOW_S,
    PLANT_STAY,
    foot_groups,
    foot_plants,
)
from ..errors import MotionError
from ..motion import Motion
from .characters import split_characters, without_prefix

Event = dict[str, Any]

EVENT_KINDS = ("contacts", "beats", "labels")
"""What ``events`` may ask for (CLI ``--events``, HTTP ``events=``)."""


def contact_runs(motion: Motion, feet: Sequence[tuple[int, ...]] | None = None) -> list[tuple[int, int, int]]:
    """The foot plants of ``motion``: ``(joint, start frame, end frame exclusive)`` per plant, the
    joint being the foot's ankle (:func:`motion.contacts.foot_plants`: one plant whichever of the
    foot's joints touches, debounced so that their number does not depend on the frame rate).

    ``feet``: one group of joints per foot, ankle first (default
    :func:`motion.contacts.foot_groups`: by the naming convention's roles, else by name; a
    character with other names passes its own, e.g. from a retargeting's role map). A motion
    without feet has no plants.
    """
    groups = foot_groups(motion.skeleton) if feet is None else [tuple(g) for g in feet]
    return [(groups[g][0], a, b) for g, a, b in foot_plants(motion, groups)]


def contact_events(
    motion: Motion,
    character: str | None = None,
    feet: Sequence[tuple[int, ...]] | None = None,
    plants: Sequence[tuple[int, int, int]] | None = None,
) -> list[Event]:
    """One ``contact`` event per foot plant of ``motion`` (:func:`contact_runs`; ``feet`` as
    there), named after the foot's ankle joint. ``plants``: the plants when the caller knows them
    better (``(group index into feet, start, end exclusive)``, e.g. a retargeted character's
    :func:`motion.retarget.report.sole_plants`: where its soles touch the floor).

    A motion without joints named like feet has no contacts (an empty list, not an error). The
    duration of a run of ``n`` frames is ``n / fps`` seconds (each frame stands for one period).
    """
    out: list[Event] = []
    names = motion.skeleton.names
    if plants is not None:
        groups = foot_groups(motion.skeleton) if feet is None else [tuple(g) for g in feet]
        runs = [(groups[g][0], a, b) for g, a, b in plants]
    else:
        runs = contact_runs(motion, feet)
    for j, a, b in runs:
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
