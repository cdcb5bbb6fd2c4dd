"""``segue build``, ``synth``, ``graph`` and ``graph-edit``: jobs run in this process on database
directories (:mod:`workers.local`, :mod:`workers.movement_graphs`), with their progress echoed.

Only the standard library at module level (each command imports what it needs).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..summaries import count, quality_summary

if TYPE_CHECKING:
    from schemas import JobEvent
    from schemas.databases import DatabaseSummary


def _validation_message(exc: Any) -> str:
    """A pydantic ``ValidationError`` in one line (its first five problems)."""
    parts = []
    for err in exc.errors()[:5]:
        where = ".".join(str(p) for p in err["loc"]) or "(top level)"
        parts.append(f"{where}: {err['msg']}")
    more = f" (+{len(exc.errors()) - 5} more)" if len(exc.errors()) > 5 else ""
    return "; ".join(parts) + more


def _echo(event: JobEvent) -> None:
    from schemas import EventType

    if event.type == EventType.progress:
        print(
            f"  {100 * event.data.get('fraction', 0):5.1f}%  {event.data.get('message', '')}", file=sys.stderr
        )
    elif event.type in (EventType.solution, EventType.alternative):
        verdict = "" if event.data.get("ok") is None else (" ok" if event.data["ok"] else " NOT ok")
        print(
            f"  {event.type.value} {event.data['result']}: score {event.data['score']:.6g} "
            f"after {event.data['elapsed_ms']:.0f} ms,{verdict}",
            file=sys.stderr,
        )
    elif event.type == EventType.failed:
        print(f"  failed: {event.data['error']['message']}", file=sys.stderr)


def _load_plugins() -> None:
    """The engine plugins named by the settings (``SEGUE_ENGINE_PLUGINS``)."""
    from engines.registry import load_plugins
    from workers.settings import get_settings

    load_plugins(get_settings().engine_plugins)


def cmd_build(args: argparse.Namespace) -> int:
    from workers.local import EventWriter, build_to_dir

    _load_plugins()

    spec_path = Path(args.spec)
    with _events_sink(args.events) as sink:
        info = build_to_dir(
            spec_path, Path(args.out), EventWriter("build", sink, None if args.quiet else _echo)
        )
    if not args.quiet:
        print(
            f"built {info.kind} database {info.id[:12]} in {args.out}: {count(len(info.clips), 'clip')}, "
            f"{info.frames} frames at {info.fps:g} fps"
        )
        for line in kept_lines(Path(args.out)):
            print(line)
    return 0


def kept_lines(db_dir: Path, limit: int | None = 20, summary: DatabaseSummary | None = None) -> list[str]:
    """What a graph build kept and left out (the ``graph`` part of the database's summary, read
    from ``db_dir`` unless given), one line per dropped clip up to ``limit`` (``None``: every one);
    no lines for other kinds of database."""
    from workers.summary import database_dir_summary

    kept = (summary or database_dir_summary(db_dir)).graph
    if kept is None:
        return []
    total = kept.kept_frames + kept.dropped_frames
    lines = [
        f"graph ({kept.candidates} transitions): kept {count(kept.kept_clips, 'clip')}, "
        f"{kept.kept_frames} of {total} frames ({kept.moving_frames} in locomotion), "
        f"{kept.leaf_edges} transitions; "
        f"left out {count(len(kept.dropped), 'clip')}, {kept.dropped_frames} frames"
        + (":" if kept.dropped else "")
    ]
    shown = kept.dropped if limit is None else kept.dropped[:limit]
    lines += [f"  {d.clip} ({d.frames} frames): {d.reason}" for d in shown]
    if len(kept.dropped) > len(shown):
        lines.append(
            f"  ... and {len(kept.dropped) - len(shown)} more (`segue inspect {db_dir}` lists them all; "
            "served: GET /v1/databases/{id}, summary.graph)"
        )
    return lines


def cmd_synth(args: argparse.Namespace) -> int:
    from motion import MotionError
    from schemas import EventType
    from workers.local import EventWriter, synth_from_dir, write_result

    _load_plugins()

    with _events_sink(args.events) as sink:
        writer = EventWriter("local", sink, None if args.quiet else _echo)
        result = synth_from_dir(Path(args.request), Path(args.db), writer, args.budget, args.feet)
    if result is None:
        failed = [e for e in writer.events if e.type == EventType.failed]
        msg = failed[-1].data["error"]["message"] if failed else "no result"
        raise MotionError(f"synthesis failed: {msg}")
    motion, report = result
    for note in write_result(motion, report, Path(args.out), Path(args.report) if args.report else None):
        print(f"segue: note: {note}", file=sys.stderr)
    if not args.quiet:
        print(f"wrote {args.out}: {motion.num_frames} frames at {motion.fps:g} fps, score {report.score:.6g}")
        print(quality_summary(report))
    return 0


def cmd_graph(args: argparse.Namespace) -> int:
    from workers.movement_graphs import graph_of_dir

    graph = graph_of_dir(Path(args.db))
    if args.json:
        print(graph.model_dump_json(indent=2))
        return 0
    parent = f", derived from {graph.derived_from.parent[:12]}" if graph.derived_from else ""
    print(
        f"database {graph.database[:12]}{parent}: {len(graph.groups)} groups, "
        f"{len(graph.transitions)} transitions, {graph.beats_per_movement} beats per movement"
        + ("" if graph.strongly_connected else " (NOT strongly connected)")
    )
    if graph.start_only_groups or graph.unreachable_groups:
        print(f"start-only groups {graph.start_only_groups}, unreachable groups {graph.unreachable_groups}")
    for g in graph.groups:
        r = g.representative
        mirror = " mirrored" if r.mirrored else ""
        print(
            f"group {g.id:3d}: {g.size:3d} movements, e.g. {r.clip}{mirror} frames "
            f"{r.start_frame}-{r.end_frame} ({r.start_s:.2f}-{r.end_s:.2f} s)"
        )
    for t in graph.transitions:
        tag = "" if t.learned else "  (added)"
        print(
            f"{t.source:3d} -> {t.target:3d}  P {t.probability:.3f}  kinematic {t.kinematic:.3f}  "
            f"behavioural {t.behavioural:.3f}{tag}"
        )
    return 0


def cmd_graph_edit(args: argparse.Namespace) -> int:
    from schemas.movement_graph import GraphEdits
    from workers.movement_graphs import derive_dir

    data = json.loads(Path(args.edits).read_bytes())
    body = GraphEdits.model_validate({"edits": data} if isinstance(data, list) else data)
    info = derive_dir(Path(args.db), body, Path(args.out))
    if not args.quiet:
        print(f"derived database {info.id[:12]} in {args.out}: {len(body.edits)} edits of {args.db}")
    return 0


class _events_sink:  # noqa: N801 - a tiny context manager used like a function
    def __init__(self, path: str | None) -> None:
        self.path = path
        self.fh: Any = None

    def __enter__(self) -> Any:
        if self.path:
            self.fh = open(self.path, "w", encoding="utf-8")
        return self.fh

    def __exit__(self, *exc: object) -> None:
        if self.fh is not None:
            self.fh.close()
