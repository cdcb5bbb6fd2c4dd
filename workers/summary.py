"""The summary of a ready database (:class:`schemas.databases.DatabaseSummary`): what a client that
did not build it needs (the clips, the label vocabulary, the skeleton, the units), from the stored
spec and the database arrays' library part (a few small arrays read from the npz, not the whole
database)."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from motion.ground import body_root
from motion.serialize import skeleton_from_arrays
from schemas.clips import LabelRange
from schemas.databases import ClipSummary, DatabaseSummary, DroppedClip, GraphKept, SkeletonSummary

from .store import NotFoundError, Store

Role = Literal["control", "target", "leader", "follower"]
ControlKind = Literal["motion", "path"]

STATIC_M = 1e-3
"""Joint 0 moving less than this on the floor (metres) over every clip is a static ground node."""

_KEYS = ("names", "frame_counts", "fps", "root_positions")
_REPORTS = ("graph.report",)


def _library_arrays(npz: bytes | Mapping[str, Any]) -> dict[str, Any]:
    """The ``library.*`` arrays of a database (skeleton, clip names and frame counts, joint 0's
    positions), read without loading the engine's own arrays (from the bytes of an ``.npz``, or
    a lazily read mapping: :meth:`workers.store.Store.open_database`)."""
    out: dict[str, Any] = {}
    if isinstance(npz, Mapping):
        for key in npz:
            wanted = key.startswith("library.skeleton.") or key.removeprefix("library.") in _KEYS
            if wanted or key in _REPORTS:
                out[key] = np.asarray(npz[key])
        return out
    with zipfile.ZipFile(io.BytesIO(npz)) as zf:
        for member in zf.namelist():
            key = member.removesuffix(".npy")
            wanted = key.startswith("library.skeleton.") or key.removeprefix("library.") in _KEYS
            if wanted or key in _REPORTS:
                with zf.open(member) as fh:
                    out[key] = np.lib.format.read_array(fh, allow_pickle=False)
    return out


def summarize(
    spec: dict[str, Any], npz: bytes | Mapping[str, Any], source_units: dict[str, str]
) -> DatabaseSummary:
    """The summary of a database from its stored ``spec`` (clips resolved to ids, with names), its
    arrays ``npz`` and the units of each uploaded clip (by id)."""
    arrays = _library_arrays(npz)
    skeleton = skeleton_from_arrays(arrays, "library.skeleton.")
    names = [str(n) for n in arrays["library.names"]]
    counts = [int(c) for c in arrays["library.frame_counts"]]
    root = np.asarray(arrays["library.root_positions"])[:, [0, 2]]
    ends = np.cumsum(counts)
    static = all(
        float(np.ptp(root[e - c : e], axis=0).max(initial=0.0)) < STATIC_M
        for c, e in zip(counts, ends, strict=True)
    )
    hips = body_root(skeleton)
    if static and hips == 0:  # no hip names: the first joint under the ground node
        hips = next((j for j, p in enumerate(skeleton.parents) if p == 0), 0)
    roles: dict[str, Role] = {}
    for pair in spec.get("pairs") or []:
        roles[pair["target"]] = "target"
        if pair.get("control"):
            roles[pair["control"]] = "control"
    for couple in spec.get("partners") or []:
        roles[couple["leader"]] = "leader"
        roles[couple["follower"]] = "follower"
    clips = []
    entries = list(spec["clips"]) + [{}] * (len(names) - len(spec["clips"]))  # mirror images follow
    for entry, name, count in zip(entries, names, counts, strict=True):
        units = entry.get("units") or source_units.get(entry.get("clip") or "")
        labels = [LabelRange.model_validate(lb) for lb in entry.get("labels") or []]
        clips.append(
            ClipSummary(name=name, frames=count, source_units=units, labels=labels, role=roles.get(name))
        )
    graph = graph_kept(arrays["graph.report"]) if "graph.report" in arrays else None
    control: ControlKind | None = None
    if spec["kind"] == "control":
        control = "motion" if any(p.get("control") for p in spec.get("pairs") or []) else "path"
    return DatabaseSummary(
        kind=spec["kind"],
        fps=float(arrays["library.fps"]),
        clips=clips,
        labels=sorted({lb.label for c in clips for lb in c.labels}),
        skeleton=SkeletonSummary(
            joints=list(skeleton.names),
            parents=[int(p) for p in skeleton.parents],
            hips=skeleton.names[hips],
            static_root=static,
        ),
        control=control,
        couples=bool(spec.get("partners")),
        graph=graph,
    )


def graph_kept(report_json: Any) -> GraphKept | None:
    """The kept-component part of a graph build's report (``graph.report``, 0-d JSON text);
    ``None`` for databases built before the report had it."""
    report = json.loads(str(report_json))
    kept = report.get("kept")
    if kept is None:
        return None
    return GraphKept(
        candidates=report.get("candidates", "all_pairs"),
        leaf_edges=int(report["leaf_edges"]),
        kept_clips=int(kept["clips"]),
        kept_frames=int(kept["frames"]),
        moving_frames=int(kept["moving_frames"]),
        dropped_frames=int(report["dropped_frames"]),
        dropped=[DroppedClip.model_validate(d) for d in report["dropped_clips"]],
    )


def database_summary(store: Store, db_id: str) -> DatabaseSummary:
    """The summary of a ready database of the store (raises ``NotFoundError`` when it has no data)."""
    spec = store.database_spec(db_id)
    units: dict[str, str] = {}
    for entry in spec.get("clips") or []:
        clip_id = entry.get("clip")
        if clip_id:
            try:
                units[clip_id] = store.clip_info(clip_id).units
            except NotFoundError:  # a clip deleted since the build: its units are unknown
                continue
    with store.open_database(db_id) as arrays:
        return summarize(spec, arrays, units)
