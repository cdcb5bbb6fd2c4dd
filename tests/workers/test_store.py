"""The durable store: content addressing, atomic writes, and nothing lost on bad input."""

from __future__ import annotations

from pathlib import Path

import pytest

from motion import BvhError
from motion.samples import sample_path
from workers.store import NotFoundError, Store


def test_clips_are_content_addressed(tmp_path: Path) -> None:
    store = Store(tmp_path)
    data = sample_path("walk").read_bytes()
    a = store.put_clip("walk.bvh.gz", data)
    b = store.put_clip("again.bvh.gz", data)
    assert a.id == b.id and a.name == "walk.bvh.gz"  # stored once, first name kept
    assert a.frames == 317 and a.units == "cm" and 1.2 < a.height_m < 1.8
    assert store.clip_bytes(a.id) == data
    assert store.find_clip("walk.bvh.gz").id == a.id
    assert store.find_clip("walk.bvh").id == a.id
    assert [c.id for c in store.list_clips()] == [a.id]
    store.delete_clip(a.id)
    with pytest.raises(NotFoundError):
        store.clip_info(a.id)


def test_bad_upload_changes_nothing(tmp_path: Path) -> None:
    store = Store(tmp_path)
    good = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    before = sorted(p.name for p in (tmp_path / "clips").iterdir())
    with pytest.raises(BvhError, match="bad.bvh:2"):
        store.put_clip("bad.bvh", b"HIERARCHY\nJOINT oops\n")
    assert sorted(p.name for p in (tmp_path / "clips").iterdir()) == before
    assert store.clip_info(good.id) == good


@pytest.mark.parametrize("ref", ["../etc/passwd", "", "A" * 200, "abc/def"])
def test_ids_cannot_escape_the_store(tmp_path: Path, ref: str) -> None:
    store = Store(tmp_path)
    with pytest.raises(NotFoundError):
        store.clip_bytes(ref)
    with pytest.raises(NotFoundError):
        store.job_info(ref)
