"""The summary of a ready database (:class:`schemas.databases.DatabaseSummary`): what a client that
did not build it needs (the clips, the label vocabulary, the skeleton, the units), from the stored
spec and the database arrays' library part (a few small arrays read from the npz, not the whole
database)."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from engines.registry import kind_class
from motion.ground import body_root
from motion.serialize import skeleton_from_arrays
from motion.skeleton import Skeleton
from schemas.clips import LabelRange
from schemas.databases import ClipSummary, DatabaseSummary, SkeletonSummary

from .store import NotFoundError, Store

STATIC_M = 1e-3
"""Joint 0 moving less than this on the floor (metres) over every clip is a static ground node."""

_KEYS = ("names", "frame_counts", "fps", "root_positions", "labels")


def _library_arrays(npz: bytes | Mapping[str, Any], extra: tuple[str, ...] = ()) -> dict[str, Any]:
    """The ``library.*`` arrays of a database (skeleton, clip names and frame counts, joint 0's
    positions) and the ``extra`` ones named, read without loading the engine's other arrays (from
    the bytes of an ``.npz``, or a lazily read mapping: :meth:`workers.store.Store.open_database`)."""
    out: dict[str, Any] = {}
    if isinstance(npz, Mapping):
        for key in npz:
            wanted = key.startswith("library.skeleton.") or key.removeprefix("library.") in _KEYS
            if wanted or key in extra:
                out[key] = np.asarray(npz[key])
        return out
    with zipfile.ZipFile(io.BytesIO(npz)) as zf:
        for member in zf.namelist():
            key = member.removesuffix(".npy")
            wanted = key.startswith("library.skeleton.") or key.removeprefix("library.") in _KEYS
            if wanted or key in extra:
                with zf.open(member) as fh:
                    out[key] = np.lib.format.read_array(fh, allow_pickle=False)
    return out


def hip_height_m(skeleton: Skeleton) -> float | None:
    """The hips' height above the mean of the two ankles in the skeleton's zero pose (metres: a
    database's skeleton is in metres), hips and feet found as retargeting finds them; None when
    they are not, or when that pose does not stand (hips not above the ankles)."""
    from motion.retarget.names import detect_roles

    roles = detect_roles(skeleton).joints
    if any(r not in roles for r in ("Hips", "LeftFoot", "RightFoot")):
        return None
    y = np.zeros(skeleton.num_joints)
    for j, p in enumerate(skeleton.parents):  # parents come before their children
        y[j] = skeleton.offsets[j, 1] + (y[p] if p >= 0 else 0.0)
    drop = float(y[roles["Hips"]] - 0.5 * (y[roles["LeftFoot"]] + y[roles["RightFoot"]]))
    return round(drop, 6) if np.isfinite(drop) and drop > 0 else None


def summarize(
    spec: dict[str, Any], npz: bytes | Mapping[str, Any], source_units: dict[str, str]
) -> DatabaseSummary:
    """The summary of a database from its stored ``spec`` (clips resolved to ids, with names), its
    arrays ``npz`` and the units of each uploaded clip (by id)."""
    engine = kind_class(spec["kind"])
    arrays = _library_arrays(npz, engine.summary_arrays)
    own = engine.summarize(spec, arrays)
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
    roles = own.roles
    entries = list(spec["clips"])
    stored_labels = json.loads(str(arrays["library.labels"])) if "library.labels" in arrays else None
    if stored_labels is not None and len(stored_labels) != len(names):
        stored_labels = None
    clips = []
    for i, (source, name, count) in enumerate(
        zip(engine.clip_sources(spec, len(names)), names, counts, strict=True)
    ):
        entry = entries[source] if source is not None else {}
        units = entry.get("units") or source_units.get(entry.get("clip") or "")
        # the labels the database holds: a mirror image's sides exchanged, a copy's on its frames
        held = stored_labels[i] if stored_labels is not None else entry.get("labels") if source == i else None
        labels = [LabelRange.model_validate(lb) for lb in held or []]
        clips.append(
            ClipSummary(name=name, frames=count, source_units=units, labels=labels, role=roles.get(name))
        )
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
            hip_height_m=hip_height_m(skeleton),
        ),
        control=own.control,
        couples=own.couples,
        graph=own.graph,
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


def database_dir_summary(db_dir: Path) -> DatabaseSummary:
    """The summary of a database directory ``segue build`` wrote (its ``spec.json`` and
    ``data.npz``; the clips' units as the spec gives them)."""
    spec = json.loads((db_dir / "spec.json").read_bytes())
    return summarize(spec, (db_dir / "data.npz").read_bytes(), {})
