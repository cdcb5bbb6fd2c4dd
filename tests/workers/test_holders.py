"""Holders of content-addressed things against the real stores (a local directory and a moto S3
server): concurrent holds are never lost, a delete racing another principal's upload of the same
bytes never loses that principal's clip, a delete on a local store writes nothing first, and
owners stored as a plain list (before per-principal records) still read."""

from __future__ import annotations

import hashlib
import json
import threading
from pathlib import Path

import pytest

from motion.samples import sample_path
from workers import holders
from workers.store import NotFoundError, Store

TRIALS = 25
GUARD_S = 120.0


@pytest.fixture(params=["local", "s3"])
def any_store(request: pytest.FixtureRequest, tmp_path: Path) -> Store:
    if request.param == "local":
        return Store(tmp_path / "data")
    return Store(request.getfixturevalue("s3_url"), tmp_path / "api")


def _upload(store: Store, principal: str, name: str, data: bytes) -> None:
    """What ``POST /v1/clips`` does with bytes already checked: store them unless stored, then hold
    them (restoring them when another holder's delete removed them meanwhile)."""
    try:
        info = store.clip_info(hashlib.sha256(data).hexdigest())
    except NotFoundError:
        info = store.put_clip(name, data)
    store.add_owner("clips", info.id, principal, {"name": name}, lambda: store.restore_clip(info, data))


def _race(*actions: object) -> None:
    barrier = threading.Barrier(len(actions))
    errors: list[BaseException] = []

    def run(action: object) -> None:
        try:
            barrier.wait(GUARD_S)
            action()  # type: ignore[operator]
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(a,)) for a in actions]
    for t in threads:
        t.start()
    for t in threads:
        t.join(GUARD_S)
    assert not any(t.is_alive() for t in threads), "a racing thread hung"
    assert not errors, errors


def test_a_delete_racing_another_principals_upload_never_loses_its_clip(any_store: Store) -> None:
    store = any_store
    data = sample_path("walk").read_bytes()
    for trial in range(TRIALS):
        _upload(store, "alice", "a.bvh.gz", data)
        clip_id = store.find_clip("a.bvh.gz").id
        _race(
            lambda c=clip_id: store.release("clips", c, "alice", store.delete_clip),
            lambda: _upload(store, "bob", "b.bvh.gz", data),
        )
        assert store.owners("clips", clip_id) == {"bob"}, trial
        assert store.clip_bytes(clip_id) == data, trial
        assert store.clip_info(clip_id).id == clip_id, trial
        assert store.holders("clips", clip_id)["bob"] == {"name": "b.bvh.gz"}
        assert store.release("clips", clip_id, "bob", store.delete_clip)  # the last holder deletes
        with pytest.raises(NotFoundError):
            store.clip_bytes(clip_id)
        assert store.owners("clips", clip_id) == set()


def test_concurrent_holds_are_all_recorded(any_store: Store) -> None:
    store = any_store
    info = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    names = [f"p{i}" for i in range(8)]
    _race(*[lambda n=n: store.add_owner("clips", info.id, n, {"name": n}) for n in names])
    assert store.owners("clips", info.id) == set(names)
    _race(*[lambda n=n: store.release("clips", info.id, n, store.delete_clip) for n in names[1:]])
    assert store.owners("clips", info.id) == {"p0"}
    assert store.clip_bytes(info.id)


def test_owners_written_as_a_plain_list_still_read(any_store: Store) -> None:
    store = any_store
    info = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    store.objects.put(f"clips/{info.id}.owners", json.dumps(["alice", "bob"]).encode())
    assert store.owners("clips", info.id) == {"alice", "bob"}
    assert store.holders("clips", info.id) == {"alice": {}, "bob": {}}
    assert not store.add_owner("clips", info.id, "alice")  # held already
    assert not store.release("clips", info.id, "bob", store.delete_clip)
    assert store.holders("clips", info.id) == {"alice": {}}
    assert store.release("clips", info.id, "alice", store.delete_clip)
    assert not store.objects.exists(f"clips/{info.id}.bvh")


def test_the_last_holders_delete_writes_nothing_on_a_local_store(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = Store(tmp_path / "data")
    info = store.put_clip("walk.bvh.gz", sample_path("walk").read_bytes())
    store.add_owner("clips", info.id, "alice", {"name": "walk.bvh.gz"})

    def full(*args: object, **kwargs: object) -> bool:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(store.objects, "put", full)
    assert store.release("clips", info.id, "alice", store.delete_clip)
    assert not (tmp_path / "data" / "clips" / f"{info.id}.bvh").exists()


def test_a_stale_deleting_marker_is_taken_over(s3_store: Store, monkeypatch: pytest.MonkeyPatch) -> None:
    """A deleter that died between its marker and its delete does not block uploads for ever."""
    monkeypatch.setattr(holders, "STALE_S", 0.2)
    data = sample_path("walk").read_bytes()
    info = s3_store.put_clip("walk.bvh.gz", data)
    s3_store.objects.put(f"clips/{info.id}.owners", holders.Holders(deleting=True).to_bytes())
    s3_store.objects.delete(f"clips/{info.id}.bvh")  # it got as far as the bytes
    assert s3_store.owners("clips", info.id) == set()  # being deleted: nobody holds it
    s3_store.add_owner("clips", info.id, "bob", {"name": "b"}, lambda: s3_store.restore_clip(info, data))
    assert s3_store.owners("clips", info.id) == {"bob"} and s3_store.clip_bytes(info.id) == data


def test_inputs_resolve_by_the_holders_own_name(store: Store) -> None:
    info = store.put_file("alice.mid", b"MThd shared bytes")
    store.add_owner("files", info.id, "alice", {"name": "alice.mid"})
    store.add_owner("files", info.id, "bob", {"name": "bob.mid"})
    assert store.find_input("bob.mid", holder="bob") == info.id
    assert store.find_input("alice.mid", holder="alice") == info.id
    with pytest.raises(NotFoundError):
        store.find_input("bob.mid", holder="alice")
    assert store.find_input("alice.mid") == info.id  # no holder: the shared name


def test_a_database_delete_on_s3_removes_its_owners_object_last(
    s3_store: Store, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The owners object holds the delete's marker that a concurrent re-post of the spec waits on,
    so it must outlive every other object of the database (not go in one batch with them)."""
    from tests.workers.conftest import add_database

    db_id = add_database(s3_store)
    s3_store.add_owner("databases", db_id, "alice", {"name": "walks"})
    deleted: list[str] = []
    real_delete = s3_store.objects.delete

    def recording(key: str) -> None:
        deleted.append(key)
        real_delete(key)

    monkeypatch.setattr(s3_store.objects, "delete", recording)
    assert s3_store.release("databases", db_id, "alice", s3_store.delete_database)
    assert len(deleted) > 2 and deleted[-1] == f"databases/{db_id}/owners"
    assert not s3_store.objects.list(f"databases/{db_id}")
