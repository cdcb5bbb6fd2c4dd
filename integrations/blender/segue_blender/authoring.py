"""Constraints authored in a Blender scene, as a Segue request (plain data in, JSON out; the
``bpy`` side, :mod:`.scene`, reads the scene into these types).

* an Empty with the custom property ``segue_frame`` is a body goal at that scene frame: its floor
  position, and its facing (its local -Y, Blender's forward) as the heading when it carries
  ``segue_heading`` (true); ``segue_dancer`` (an index) gives it to one dancer of several;
* a curve is the walked path of a control database driven by paths, at a speed (m/s): its length
  and the speed time it; for a rhythm request it is the floor path the dancers follow;
* timeline markers named after labels paint an annotation timeline: each marker holds from its
  frame to the next marker; ``walk`` is "do", ``!jump`` (or ``-jump``) "don't", several labels
  separated by commas or spaces, a marker named ``-`` or ``~`` ends the painting (don't care);
* the scene's sound strip (a recording, uploaded) or a BPM is the music of a rhythm request;
* another armature's action (uploaded as a clip) is the leader of a control database driven by a
  leader's motion (the Partner tool).

Times: the scene plays from ``frame_start`` to ``frame_end`` at ``fps``; a goal at frame ``f`` is
at ``(f - start) / fps`` seconds of the motion, which is keyed from ``start``. Positions go
through a :class:`~.axes.SegueFrame` (an anchor and the character's size over the performers').
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

from .axes import SegueFrame, heading_deg

PATH_FPS = 30.0
"""Points per second of a path sent as a control trajectory."""


ENGINE_OF_KIND = {"graph": "graph", "control": "control", "annotated": "annotations", "rhythm": "rhythm",
                  "clips": "clip"}  # fmt: skip
"""The engine that answers requests on each database kind."""


class AuthoringError(ValueError):
    """Scene constraints that make no request (a goal outside the frame range, no path...)."""


@dataclass(frozen=True, slots=True)
class Goal:
    """A body goal: the scene frame, the Blender position, the Blender floor direction it faces
    (None: heading free) and the dancer it belongs to."""

    name: str
    frame: float
    position: tuple[float, float, float]
    facing: tuple[float, float] | None = None
    dancer: int = 0


@dataclass(frozen=True, slots=True)
class Marker:
    """A timeline marker: its name (labels) and scene frame."""

    name: str
    frame: int


@dataclass(frozen=True, slots=True)
class Timing:
    """The scene's frame range and rate (``fps`` = render fps / fps base)."""

    start: int
    end: int
    fps: float

    def seconds(self, frame: float) -> float:
        return (frame - self.start) / self.fps

    @property
    def duration_s(self) -> float:
        return (self.end - self.start) / self.fps


@dataclass(slots=True)
class SceneInputs:
    """What the scene says: goals, a path (Blender points), markers, music and a leader."""

    timing: Timing
    goals: list[Goal] = field(default_factory=list)
    path: list[tuple[float, float, float]] | None = None
    speed: float = 1.3
    markers: list[Marker] = field(default_factory=list)
    bpm: float | None = None
    audio: str | None = None
    """An uploaded recording's id (the scene's sound strip)."""
    audio_start: int | None = None
    """The scene frame the recording starts at."""
    leader: str | None = None
    """An uploaded clip's name: the leader's motion, from the scene's start frame."""
    dancers: int = 1


@dataclass(frozen=True, slots=True)
class Authored:
    """A request and the scene frame its motion starts at."""

    request: dict[str, Any]
    start_frame: int


def _heading(goal: Goal) -> float | None:
    return None if goal.facing is None else heading_deg(goal.facing)


def _check_goals(goals: Sequence[Goal], timing: Timing) -> None:
    for g in goals:
        if not (timing.start <= g.frame <= timing.end):
            raise AuthoringError(
                f"goal {g.name!r} is at frame {g.frame:g}, "
                f"outside the scene's frames {timing.start}-{timing.end}"
            )


def body_constraints(goals: Sequence[Goal], timing: Timing, frame: SegueFrame) -> list[dict[str, Any]]:
    """Graph ``body`` constraints (``time_s``, ``position``, optional ``heading_deg``) in time order."""
    _check_goals(goals, timing)
    out = []
    for g in sorted(goals, key=lambda g: g.frame):
        c: dict[str, Any] = {"type": "body", "time_s": round(timing.seconds(g.frame), 6),
                             "position": _rounded(frame.floor(g.position))}  # fmt: skip
        h = _heading(g)
        if h is not None:
            c["heading_deg"] = round(h, 4)
        out.append(c)
    return out


def _rounded(p: tuple[float, float]) -> list[float]:
    return [round(p[0], 6), round(p[1], 6)]


def resample_path(points: Sequence[Sequence[float]], spacing: float) -> list[tuple[float, float]]:
    """A floor polyline ``[(x, y), ...]`` resampled every ``spacing`` (same units) along its length,
    from its first point; the last sample is its end. ``AuthoringError`` for a path of no length."""
    if spacing <= 0:
        raise AuthoringError("the path's spacing must be positive")
    pts = [(float(p[0]), float(p[1])) for p in points]
    segs = [math.dist(a, b) for a, b in pairwise(pts)]
    total = sum(segs)
    if len(pts) < 2 or total <= 1e-9:
        raise AuthoringError("the path has no length")
    n = max(2, int(math.floor(total / spacing)) + 1)
    out: list[tuple[float, float]] = []
    k, walked = 0, 0.0
    for i in range(n):
        s = min(i * spacing, total)
        while k < len(segs) - 1 and walked + segs[k] < s:
            walked += segs[k]
            k += 1
        u = 0.0 if segs[k] <= 0 else (s - walked) / segs[k]
        a, b = pts[k], pts[k + 1]
        out.append((a[0] + (b[0] - a[0]) * u, a[1] + (b[1] - a[1]) * u))
    if math.dist(out[-1], pts[-1]) > 1e-9:
        out.append(pts[-1])
    return out


def trajectory(path: Sequence[Sequence[float]], speed: float, frame: SegueFrame) -> dict[str, Any]:
    """A control trajectory (``fps``, ``points`` ``[x, z]``) walking ``path`` (Blender points) at
    ``speed`` m/s of the character, in Segue's frame (lengths divided by its scale)."""
    if not (math.isfinite(speed) and speed > 0):
        raise AuthoringError(f"the walking speed must be positive (m/s), not {speed!r}")
    floor = [frame.floor(tuple(p)) for p in path]
    pts = resample_path(floor, frame.length(speed) / PATH_FPS)
    return {"fps": PATH_FPS, "points": [_rounded(p) for p in pts]}


_TOKEN = re.compile(r"[,\s]+")


def timeline(markers: Sequence[Marker], timing: Timing, db_fps: float, frames: int) -> list[dict[str, Any]]:
    """Annotation timeline entries from markers (module docstring), in output frames at ``db_fps``."""
    ordered = sorted((m for m in markers if timing.start <= m.frame <= timing.end), key=lambda m: m.frame)
    out: list[dict[str, Any]] = []
    for i, m in enumerate(ordered):
        start = round(timing.seconds(m.frame) * db_fps)
        end = frames if i + 1 == len(ordered) else round(timing.seconds(ordered[i + 1].frame) * db_fps)
        end = min(end, frames)
        if end <= start:
            continue
        for token in filter(None, _TOKEN.split(m.name.strip())):
            if token in ("-", "~"):
                continue
            value = -1 if token[0] in "!-" else 1
            label = token.lstrip("!-")
            if label:
                out.append({"label": label, "start": start, "end": end, "value": value})
    return out


def _frames(timing: Timing, summary: Mapping[str, Any]) -> int:
    """Output frames at the database's rate spanning the scene's first to last frame, both
    included (a goal on the last frame is on the motion's last frame)."""
    if timing.duration_s <= 0:
        raise AuthoringError("the scene's frame range is empty: set its end after its start")
    return max(2, round(timing.duration_s * float(summary.get("fps") or 30.0)) + 1)


def label_ranges(markers: Sequence[Marker], first: int, last: int) -> list[dict[str, Any]]:
    """A clip's labels from its action's pose markers (same names as the timeline's: ``walk``,
    ``!jump``, ``-`` ends): each holds from its frame to the next marker, in the clip's own
    frames (0 at the action's ``first`` frame, ``last`` its last), as an annotated database's
    ``labels`` take them."""
    ordered = sorted((m for m in markers if first <= m.frame <= last), key=lambda m: m.frame)
    out: list[dict[str, Any]] = []
    for i, m in enumerate(ordered):
        start = m.frame - first
        end = (ordered[i + 1].frame if i + 1 < len(ordered) else last + 1) - first
        if end <= start:
            continue
        for token in filter(None, _TOKEN.split(m.name.strip())):
            if token in ("-", "~"):
                continue
            label = token.lstrip("!-")
            if label:
                out.append(
                    {"label": label, "start": start, "end": end, "value": -1 if token[0] in "!-" else 1}
                )
    return out


def _merge_list(request: dict[str, Any], key: str, items: list[dict[str, Any]]) -> None:
    request[key] = [*request.get(key, []), *items]


def scene_request(
    base: Mapping[str, Any],
    summary: Mapping[str, Any],
    scene: SceneInputs,
    frame: SegueFrame,
    dancer_frames: Sequence[SegueFrame] | None = None,
) -> Authored:
    """``base`` (a request as the HTTP API takes it, ``database`` set) completed with what the
    scene authors for the database's kind (``summary``: the database's summary from the API).
    What ``base`` already says wins; scene constraints are added to its lists. ``dancer_frames``
    gives each dancer of several its own frame (the same anchor, its own character's scale: each
    is put on its own character, scaled by its own ratio)."""
    req: dict[str, Any] = copy.deepcopy(dict(base))
    kind = str(summary.get("kind", ""))
    timing = scene.timing
    start = timing.start
    goals = list(scene.goals)
    if kind == "graph":
        req.setdefault("engine", "graph")
        if "frames" not in req and "seconds" not in req:
            req["frames"] = _frames(timing, summary)
        if scene.dancers > 1:
            chars: list[dict[str, Any]] = [dict(c) for c in req.get("characters") or []]
            chars += [{"constraints": []} for _ in range(scene.dancers - len(chars))]
            for d in range(scene.dancers):
                mine = [g for g in goals if g.dancer == d]
                own = dancer_frames[d] if dancer_frames is not None and d < len(dancer_frames) else frame
                chars[d].setdefault("constraints", [])
                chars[d]["constraints"] = [*chars[d]["constraints"], *body_constraints(mine, timing, own)]
            req["characters"] = chars
        else:
            _merge_list(req, "constraints", body_constraints(goals, timing, frame))
    elif kind == "control":
        req.setdefault("engine", "control")
        if "control" not in req:
            if summary.get("control") == "path":
                if not scene.path:
                    raise AuthoringError("a walk database needs a path: add a curve to the scene")
                req["control"] = {"trajectory": trajectory(scene.path, scene.speed, frame)}
            else:
                if not scene.leader:
                    raise AuthoringError("a partner database needs a leader: pick the leader's armature")
                req["control"] = {"bvh": scene.leader}
        bodies = [
            {"time_s": round(timing.seconds(g.frame), 6), "position": _rounded(frame.floor(g.position))}
            for g in sorted(goals, key=lambda g: g.frame)
        ]
        _check_goals(goals, timing)
        _merge_list(req, "bodies", bodies)
    elif kind == "annotated":
        req.setdefault("engine", "annotations")
        fps = float(summary.get("fps") or 30.0)
        frames = int(req.get("frames") or _frames(timing, summary))
        req["frames"] = frames
        _merge_list(req, "timeline", timeline(scene.markers, timing, fps, frames))
        _check_goals(goals, timing)
        ordered = sorted(goals, key=lambda g: g.frame)
        if ordered and "start" not in req:
            first = ordered[0]
            req["start"] = {"position": _rounded(frame.floor(first.position)),
                            "heading_deg": round(_heading(first) or 0.0, 4)}  # fmt: skip
        if len(ordered) > 1 and "end" not in req:
            last = ordered[-1]
            end: dict[str, Any] = {"position": _rounded(frame.floor(last.position))}
            if _heading(last) is not None:
                end["heading_deg"] = round(_heading(last) or 0.0, 4)
            req["end"] = end
    elif kind == "rhythm":
        req.setdefault("engine", "rhythm")
        if "music" not in req:
            if scene.audio is not None:
                start = scene.audio_start if scene.audio_start is not None else timing.start
                length = (timing.end - start) / timing.fps
                if length <= 0:
                    raise AuthoringError("the sound strip starts after the scene's last frame")
                req["music"] = {"audio": scene.audio, "duration_s": round(length, 6)}
            elif scene.bpm is not None:
                req["music"] = {"bpm": scene.bpm, "duration_s": round(timing.duration_s, 6)}
            else:
                raise AuthoringError("a rhythm database needs music: a sound strip in the scene or a BPM")
        if scene.dancers > 1 and "characters" not in req:
            req["characters"] = scene.dancers // 2 if req.get("couples") else scene.dancers
        if scene.path and "path" not in req and "directions" not in req:
            req["path"] = [_rounded(frame.floor(p)) for p in scene.path]
            req.setdefault("speed", round(frame.length(scene.speed), 6))
        _check_goals(goals, timing)
        if goals and "start" not in req:
            first = sorted(goals, key=lambda g: g.frame)[0]
            req["start"] = {"position": _rounded(frame.floor(first.position)),
                            "heading_deg": round(_heading(first) or 0.0, 4)}  # fmt: skip
    elif kind == "clips":
        req.setdefault("engine", "clip")
        goal = sorted(goals, key=lambda g: g.frame)[0] if goals else None
        if goal is not None:
            req.setdefault("position", _rounded(frame.floor(goal.position)))
            if _heading(goal) is not None:
                req.setdefault("heading_deg", round(_heading(goal) or 0.0, 4))
    else:
        raise AuthoringError(f"no scene authoring for databases of kind {kind!r}")
    return Authored(req, start)


def goal_errors(report: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The body goals of a report (its ``constraint_errors`` entries ``body[i]``, ``c<d>.body[i]``,
    and an annotation request's ``start`` / ``end``): dancer, index (the goals' time order),
    frame, error (cm, degrees) and whether it is met."""
    entries = report.get("constraint_errors") or {}
    out = []
    for name, entry in entries.items() if isinstance(entries, Mapping) else ():
        m = re.fullmatch(r"(?:c(\d+)\.)?body\[(\d+)\]", str(name))
        if m is not None:
            dancer, index = int(m.group(1) or 0), int(m.group(2))
        elif name in ("start", "end"):
            dancer, index = 0, 0 if name == "start" else -1
        else:
            continue
        out.append(
            {
                "name": str(name),
                "dancer": dancer,
                "index": index,
                "frame": entry.get("frame"),
                "error_cm": entry.get("position_cm"),
                "tolerance_cm": entry.get("tolerance_cm", 5.0),
                "heading_deg": entry.get("heading_deg"),
                "satisfied": bool(entry.get("satisfied", False)),
            }
        )
    return out
