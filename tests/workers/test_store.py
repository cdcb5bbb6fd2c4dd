"""The durable store: content addressing, atomic writes, and nothing lost on bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion import BvhError
from motion.samples import sample_path
from workers.store import NotFoundError, Store, load_npz, npz_bytes


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


# -- one store, two backends -------------------------------------------------------------------------
@pytest.fixture(params=["local", "s3"])
def any_store(request: pytest.FixtureRequest, tmp_path: Path) -> Store:
    if request.param == "local":
        return Store(tmp_path / "data")
    return Store(request.getfixturevalue("s3_url"), tmp_path / "cache-host")


def _arrays() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(1)
    return {
        "library.names": np.array(["walk", "run"]),
        "library.fps": np.array(30.0),
        "big.table": rng.standard_normal((300, 100)).astype(np.float32),  # 120 kB: memory-mapped
        "empty": np.zeros((0, 3)),
        "odd name/with slash": np.arange(5),
    }


def test_everything_round_trips_on_either_backend(any_store: Store) -> None:
    store = any_store
    clip = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    assert store.find_input("walk.bvh") == clip.id and store.list_clips() == [clip]
    f = store.put_file("song.mid", b"MThd\x00\x00\x00\x06")
    assert store.file_info(f.id).media_type == "audio/midi" and store.input_bytes(f.id).startswith(b"MThd")
    store.put_database_arrays("db1", _arrays())
    assert store.has_database_arrays("db1") and not store.has_database_arrays("db2")
    with store.open_database("db1") as lazy:
        assert sorted(lazy) == sorted(_arrays()) and list(lazy["library.names"]) == ["walk", "run"]
    loaded = store.database_arrays("db1")
    for name, array in _arrays().items():
        assert loaded[name].dtype == array.dtype and np.array_equal(loaded[name], array)
    loaded["big.table"][0, 0] = 99.0  # copy on write: the store's bytes never change
    assert store.database_arrays("db1")["big.table"][0, 0] == _arrays()["big.table"][0, 0]
    store.append_event("j1", '{"id": 1}')
    store.append_event("j1", '{"id": 2}')
    assert store.events("j1") == ['{"id": 1}', '{"id": 2}'] and store.events("j2") == []
    store.put_export("j1", "r1.glb", b"glTF")
    assert store.export_bytes("j1", "r1.glb") == b"glTF"
    with pytest.raises(NotFoundError):
        store.export_bytes("j1", "r2.glb")


def test_a_database_stored_as_npz_is_read_and_converted(any_store: Store) -> None:
    """Databases written before arrays were stored one per object (``data.npz``) stay usable."""
    store = any_store
    arrays = {k: v for k, v in _arrays().items() if "/" not in k}
    store.objects.put("databases/old1/data.npz", npz_bytes(arrays))
    assert store.has_database_arrays("old1")
    loaded = store.database_arrays("old1")
    assert all(np.array_equal(loaded[k], v) for k, v in arrays.items())
    assert store.objects.exists("databases/old1/arrays.json")  # converted once, in the store
    assert store.objects.exists("databases/old1/data.npz")  # and nothing removed
    assert load_npz(store.database_arrays_bytes("old1")).keys() == arrays.keys()


def test_an_object_store_is_cached_on_disk_and_evicted_by_bytes(s3_url: str, tmp_path: Path) -> None:
    writer = Store(s3_url, tmp_path / "api")
    for db in ("d1", "d2", "d3"):
        writer.put_database_arrays(db, _arrays())
    size = writer.database_manifest("d1").total_bytes
    worker = Store(s3_url, tmp_path / "worker", disk_cache_bytes=2 * size)
    first = worker.database_dir("d1")
    assert first.is_relative_to(tmp_path / "worker") and (first / "arrays.json").is_file()
    assert worker.database_dir("d1") == first  # a hit: not downloaded again
    worker.database_dir("d2")
    worker.database_dir("d1")  # d1 used last: d2 is the least recently used
    worker.database_dir("d3")
    assert sorted(d for _, _, d in worker.cache.entries()) == ["d1", "d3"]
    assert worker.cache.total_bytes() <= 2 * size
    writer.delete_database("d1")
    with pytest.raises(NotFoundError):
        worker.database_dir("d1")
    assert not (tmp_path / "api" / "cache").exists()


def test_any_valid_id_is_a_plain_miss(any_store: Store) -> None:
    for lookup in (any_store.job_info, any_store.database_info, any_store.clip_info, any_store.delete_job):
        with pytest.raises(NotFoundError):
            lookup("__main__")
