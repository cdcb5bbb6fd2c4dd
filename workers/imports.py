"""Importing a database folder that ``segue build`` (or ``segue graph-edit``) wrote into the store,
under the same content id the API would give it (``segue serve --import DIR``).

A folder holds ``info.json``, ``spec.json`` (its clips as the spec file named them, each with the
``sha256`` of the clip's bytes) and ``data.npz``. The import checks that the folder is what it says:
the id in ``info.json`` must be :func:`schemas.databases.database_id` of the spec and the clips'
hashes (for a derived database: :func:`workers.movement_graphs.derived_database_id` of that parent and
its edits), and the arrays must hold a database library. The store then holds it as if it had been
built through ``POST /v1/databases``: its spec names each clip by its hash, ``ready``, no build job.
Clips given as ``sample:NAME`` are stored too (their units show in the summary); other clip files
are not copied (the folder does not hold them): upload them (``POST /v1/clips``) before asking for
label corrections, which rebuild from the clips' bytes.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from collections.abc import Iterable
from io import BytesIO
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from engines.registry import parse_database_spec
from motion import MotionError
from motion.samples import is_clip_sample, sample_name, sample_path
from schemas import DatabaseInfo, DatabaseStatus
from schemas.databases import database_id

from .movement_graphs import derived_database_id
from .store import NotFoundError, Store


class ImportFailure(ValueError):
    """The folder is not a database ``segue build`` wrote (the message names the folder and why)."""


def _read(folder: Path) -> tuple[DatabaseInfo, dict[str, Any], bytes]:
    missing = [n for n in ("info.json", "spec.json", "data.npz") if not (folder / n).is_file()]
    if missing:
        raise ImportFailure(
            f"{folder}: not a database folder written by segue build (no {', '.join(missing)})"
        )
    try:
        info = DatabaseInfo.model_validate_json((folder / "info.json").read_bytes())
        spec = json.loads((folder / "spec.json").read_bytes())
    except (ValidationError, ValueError) as exc:
        raise ImportFailure(f"{folder}: info.json or spec.json is not valid ({exc})") from None
    data = (folder / "data.npz").read_bytes()
    try:
        with zipfile.ZipFile(BytesIO(data)) as zf:
            names = zf.namelist()
    except zipfile.BadZipFile:
        raise ImportFailure(f"{folder}: data.npz is not a NumPy .npz archive") from None
    if "library.names.npy" not in names:
        raise ImportFailure(f"{folder}: data.npz holds no database library (library.names)")
    if not isinstance(spec, dict) or not isinstance(spec.get("clips"), list):
        raise ImportFailure(f"{folder}: spec.json has no clips")
    return info, spec, data


def _stored_spec(folder: Path, spec: dict[str, Any]) -> tuple[dict[str, Any], list[str], str]:
    """The spec as the store keeps it (clips by hash, named), the clips' hashes and the id they give."""
    digests, clips = [], []
    for i, entry in enumerate(spec["clips"]):
        entry = dict(entry)
        digest = entry.pop("sha256", None)
        if not isinstance(digest, str) or len(digest) != 64:
            raise ImportFailure(f"{folder}: spec.json clips[{i}] has no sha256 (not written by segue build)")
        digests.append(digest)
        clips.append(entry)
    try:
        parsed = parse_database_spec({**spec, "clips": clips})
    except (ValidationError, ValueError) as exc:
        raise ImportFailure(f"{folder}: spec.json is not a database spec ({exc})") from None
    resolved = [
        source.model_copy(update={"clip": digest, "bvh": None, "name": source.display_name()})
        for source, digest in zip(parsed.clips, digests, strict=True)
    ]
    stored = parsed.model_dump(mode="json")
    stored["clips"] = [c.model_dump(mode="json", exclude_none=True) for c in resolved]
    return stored, digests, database_id(parsed, digests)


def _store_samples(store: Store, spec: dict[str, Any], digests: list[str], owners: list[str]) -> None:
    """Store the bundled samples the spec names, when they are the bytes the folder was built from."""
    for entry, digest in zip(spec["clips"], digests, strict=True):
        try:
            name = sample_name(str(entry.get("bvh") or ""))
            if name is None or not is_clip_sample(name):
                continue
            data = sample_path(name).read_bytes()
        except MotionError:  # a sample this version does not bundle
            continue
        if hashlib.sha256(data).hexdigest() == digest:
            info = store.put_clip(sample_path(name).name, data)
            for owner in owners:
                store.add_owner("clips", info.id, owner)


def import_database_dir(store: Store, folder: Path, owners: Iterable[str]) -> tuple[DatabaseInfo, bool]:
    """Import ``folder`` into ``store``, held by each of ``owners``; returns its info and whether it
    was new (False: the store had this database ready already). Raises :class:`ImportFailure`."""
    owners = list(owners)
    info, spec, data = _read(folder)
    stored, digests, built_id = _stored_spec(folder, spec)
    expected = built_id
    if info.derived_from is not None:
        if info.derived_from.parent != built_id:
            raise ImportFailure(
                f"{folder}: derived from {info.derived_from.parent[:12]}, but its spec and clips give "
                f"{built_id[:12]} (edited by hand?)"
            )
        expected = derived_database_id(info.derived_from.parent, info.derived_from.edits)
    if info.id != expected:
        raise ImportFailure(
            f"{folder}: info.json names database {info.id[:12]}, but its spec and clips give "
            f"{expected[:12]} (edited by hand, or written by another version of Segue)"
        )
    try:
        existing = store.database_info(info.id)
    except NotFoundError:
        existing = None
    new = existing is None or existing.status != DatabaseStatus.ready
    if new:
        _store_samples(store, spec, digests, owners)
        store.put_database_arrays(info.id, data)  # the data first: never a ready info without it
        ready = info.model_copy(update={"status": DatabaseStatus.ready, "build_job": None, "error": None})
        store.put_database_info(ready, stored)
    for owner in owners:
        store.add_owner("databases", info.id, owner)
    return store.database_info(info.id), new
