"""The local database cache: the order of use survives uses closer together than the clock ticks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from engines.base import container
from workers import dbcache
from workers.dbcache import DiskCache


def _source(tmp_path: Path) -> tuple[container.Manifest, dbcache.Fetch]:
    """A database of one 4 kB array, and a fetch that copies its files from ``tmp_path/src``."""
    src = tmp_path / "src"
    manifest = container.write_dir(src, {"x": np.arange(512, dtype=np.float64)})

    def fetch(file: str, path: Path) -> None:
        path.write_bytes((src / file).read_bytes())

    return manifest, fetch


def test_uses_in_one_clock_tick_keep_their_order(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A frozen clock stands for uses within one tick of the file system's clock: the cache still
    evicts the database used least recently, not the one whose id sorts first."""
    manifest, fetch = _source(tmp_path)
    monkeypatch.setattr(dbcache.time, "time_ns", lambda: 1_700_000_000_000_000_000)
    cache = DiskCache(tmp_path / "cache", max_bytes=2 * manifest.total_bytes)
    cache.fetch("d1", manifest, fetch)
    cache.fetch("d2", manifest, fetch)
    assert cache.path_if_cached("d1") is not None  # d1 used last: d2 is the least recently used
    cache.fetch("d3", manifest, fetch)
    assert [d for _, _, d in cache.entries()] == ["d1", "d3"]
    assert cache.path_if_cached("d2") is None


def test_the_database_just_fetched_stays_when_it_alone_is_over_the_bound(tmp_path: Path) -> None:
    manifest, fetch = _source(tmp_path)
    cache = DiskCache(tmp_path / "cache", max_bytes=manifest.total_bytes // 2)
    cache.fetch("d1", manifest, fetch)
    d2 = cache.fetch("d2", manifest, fetch)
    assert [d for _, _, d in cache.entries()] == ["d2"]
    assert np.array_equal(container.load_all(d2)["x"], np.arange(512, dtype=np.float64))
