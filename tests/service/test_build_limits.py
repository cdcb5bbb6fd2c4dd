"""Database size at submission: graph databases are bounded by their estimated build work (CPU and
memory), other kinds by a frame count."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi.testclient import TestClient

from engines.graph.build import build_work
from workers.settings import Settings

from .test_api import error_of


def test_graph_databases_are_bounded_by_their_build_estimate(
    client: TestClient, walk_clip: dict[str, Any], override_settings: Callable[..., Settings]
) -> None:
    # the walk is 317 frames at 120 fps: 79 at 30 fps; the frame cap does not apply to graphs
    override_settings(max_database_frames=50, max_job_memory_mb=1, max_build_cpu_s=0)
    spec = {"kind": "graph", "clips": [{"clip": walk_clip["id"]}], "fps": 30, "candidates": "indexed"}
    err = error_of(client.post("/v1/databases", json=spec), 413, "over_budget")
    work = build_work(79, "indexed")
    assert err["details"] == {
        "frames": 79,
        "cpu_s": round(work.cpu_s),
        "memory_mb": round(work.memory_mb),
        "max_build_cpu_s": 0,
        "max_job_memory_mb": 1,
    }
    assert "SEGUE_MAX_JOB_MEMORY_MB" in err["message"]
    override_settings(max_database_frames=50, max_job_memory_mb=0, max_build_cpu_s=1)
    err = error_of(client.post("/v1/databases", json=spec), 413, "over_budget")
    assert "SEGUE_MAX_BUILD_CPU_S" in err["message"]
    override_settings(max_database_frames=50, max_job_memory_mb=4096, max_build_cpu_s=3600)
    assert client.post("/v1/databases", json=spec).status_code in (200, 202)


def test_build_estimates_grow_linearly_with_the_index_and_quadratically_without() -> None:
    small, big = build_work(100_000, "indexed"), build_work(1_000_000, "indexed")
    assert 9 < (big.cpu_s - 10) / (small.cpu_s - 10) < 11
    pairs_small, pairs_big = build_work(10_000, "all_pairs"), build_work(100_000, "all_pairs")
    assert (pairs_big.memory_mb - 400) / (pairs_small.memory_mb - 400) > 90
    # the default job memory (4 GiB) allows an indexed graph of ~600k frames, not the all-pairs one
    assert build_work(600_000, "auto").memory_mb < 4096 < build_work(400_000, "all_pairs").memory_mb
    assert build_work(1_000_000, "auto").memory_mb < 8192


def test_mirror_images_count_against_the_frame_limit(
    client: TestClient, walk_clip: dict[str, Any], override_settings: Callable[..., Settings]
) -> None:
    # 79 frames at 30 fps; with 'mirror' the database holds 158
    override_settings(max_database_frames=100)
    spec = {"kind": "annotated", "clips": [{"clip": walk_clip["id"]}], "fps": 30, "mirror": True}
    err = error_of(client.post("/v1/databases", json=spec), 413, "over_budget")
    assert err["details"] == {"frames": 158, "limit": 100}
    spec["mirror"] = False
    assert client.post("/v1/databases", json=spec).status_code in (200, 202)


def test_time_scaled_copies_count_in_the_build_estimate(
    client: TestClient, walk_clip: dict[str, Any], override_settings: Callable[..., Settings]
) -> None:
    # 79 frames at 30 fps; mirrored 158, and copies of those at 0.5 (316) and 2 (79): 553
    override_settings(max_job_memory_mb=1, max_build_cpu_s=0)
    spec: dict[str, Any] = {
        "kind": "graph",
        "clips": [{"clip": walk_clip["id"]}],
        "fps": 30,
        "candidates": "indexed",
        "mirror": True,
        "speeds": [0.5, 2.0],
    }
    err = error_of(client.post("/v1/databases", json=spec), 413, "over_budget")
    assert err["details"]["frames"] == 553
    assert err["details"]["memory_mb"] == round(build_work(553, "indexed").memory_mb)
    spec["speeds"] = [2.0]
    assert error_of(client.post("/v1/databases", json=spec), 413, "over_budget")["details"]["frames"] == 237
