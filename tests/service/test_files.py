"""Input files of requests: ``/v1/files`` uploads, resolution at submission, bytes in the worker."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from engines.registry import parse_job_request
from workers.inputs import InputError, attach_from_dir, attach_resolved, resolve_inputs
from workers.store import Store

from .conftest import wait_events

MIDI = b"MThd\x00\x00\x00\x06\x00\x00\x00\x01\x01\xe0MTrk\x00\x00\x00\x04\x00\xff\x2f\x00"


def test_upload_list_get_file(client: TestClient) -> None:
    r = client.post("/v1/files?name=song.mid", content=MIDI)
    assert r.status_code in (200, 201), r.text
    info = r.json()
    assert info["media_type"] == "audio/midi" and info["size_bytes"] == len(MIDI)
    again = client.post("/v1/files?name=song.mid", content=MIDI)
    assert again.status_code == 200 and again.json()["id"] == info["id"]
    assert any(f["id"] == info["id"] for f in client.get("/v1/files").json())
    assert client.get(f"/v1/files/{info['id']}").json()["name"] == "song.mid"
    missing = client.get("/v1/files/" + "0" * 64)
    assert missing.status_code == 404


def test_job_reads_the_input_resolved_at_submission(client: TestClient, walk_db: dict[str, Any]) -> None:
    payload = b"x" * 1234
    up = client.post("/v1/files?name=input-a.bin", content=payload).json()
    r = client.post(
        "/v1/jobs",
        json={
            "engine": "scripted",
            "database": walk_db["id"],
            "steps": 1,
            "step_s": 0,
            "input": "input-a.bin",
        },
    )
    assert r.status_code == 202, r.text
    job = r.json()
    # a later upload under the same name does not change the submitted job
    client.post("/v1/files?name=input-a.bin", content=b"y" * 10)
    events = wait_events(client, job["id"])
    assert events[-1]["type"] == "done", events
    report = client.get(f"/v1/jobs/{job['id']}/report").json()
    assert report["terms"]["input_bytes"] == 1234
    stored = client.get(f"/v1/jobs/{job['id']}").json()
    assert stored["status"] == "done" and up["id"]


def test_missing_input_is_a_422_naming_it(client: TestClient, walk_db: dict[str, Any]) -> None:
    r = client.post(
        "/v1/jobs", json={"engine": "scripted", "database": walk_db["id"], "input": "nowhere.mid"}
    )
    assert r.status_code == 422, r.text
    body = r.json()["error"]
    assert body["code"] == "input_not_found" and "nowhere.mid" in body["message"]


def test_store_resolution_by_id_and_name(tmp_path: Path) -> None:
    store = Store(tmp_path)
    a = store.put_file("a.mid", MIDI)
    request = parse_job_request({"engine": "scripted", "input": "a.mid"})
    assert resolve_inputs(store, request) == {"a.mid": a.id}
    by_id = parse_job_request({"engine": "scripted", "input": a.id})
    by_id.inputs = resolve_inputs(store, by_id)
    attach_resolved(store, by_id)
    assert by_id.input_bytes(a.id) == MIDI
    with pytest.raises(InputError, match="b.mid"):
        resolve_inputs(store, parse_job_request({"engine": "scripted", "input": "b.mid"}))


def test_cli_inputs_are_relative_to_the_request_file(tmp_path: Path) -> None:
    (tmp_path / "music").mkdir()
    (tmp_path / "music" / "s.mid").write_bytes(MIDI)
    request = parse_job_request({"engine": "scripted", "input": "music/s.mid"})
    attach_from_dir(request, tmp_path)
    assert request.input_bytes("music/s.mid") == MIDI
    absent = parse_job_request({"engine": "scripted", "input": "music/none.mid"})
    with pytest.raises(InputError, match="none.mid"):
        attach_from_dir(absent, tmp_path)
    with pytest.raises(KeyError, match="other"):
        request.input_bytes("other")


def test_recordings_are_typed_by_content_and_checked_at_submission(
    client: TestClient, tmp_path: Path
) -> None:
    wav = b"RIFF\x24\x00\x00\x00WAVEfmt " + bytes(32)
    info = client.post("/v1/files?name=song.wav", content=wav).json()
    assert info["media_type"] == "audio/wav"
    store = Store(tmp_path)
    store.put_file("song.wav", wav)
    store.put_file("notes.wav", MIDI)  # a MIDI file under a recording's name
    ok = parse_job_request({"engine": "rhythm", "music": {"audio": "song.wav"}})
    assert set(resolve_inputs(store, ok)) == {"song.wav"}
    bad = parse_job_request({"engine": "rhythm", "music": {"audio": "notes.wav"}})
    with pytest.raises(InputError, match="not a WAV, FLAC, Ogg or MP3 recording") as err:
        resolve_inputs(store, bad)
    assert err.value.code == "input_not_audio"
