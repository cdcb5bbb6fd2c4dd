"""A database directory: one .npy per array, a manifest written last, large arrays memory-mapped."""

from __future__ import annotations

import json
import mmap
from pathlib import Path

import numpy as np
import pytest

from engines import container
from engines.base import open_database


def _mapped(array: object) -> bool:
    """Whether ``array`` is backed by a memory map (somewhere down its chain of bases)."""
    while array is not None:
        if isinstance(array, np.memmap | mmap.mmap):
            return True
        array = getattr(array, "base", None)
    return False


def _arrays() -> dict[str, np.ndarray]:
    return {
        "library.names": np.array(["a", "b"]),
        "big": np.arange(40_000, dtype=np.float64),  # 320 kB: mapped
        "small": np.arange(3, dtype=np.int32),
    }


def test_round_trip_maps_large_arrays_copy_on_write(tmp_path: Path) -> None:
    manifest = container.write_dir(tmp_path / "db", _arrays())
    assert manifest.total_bytes == sum(
        (tmp_path / "db" / "arrays" / f).stat().st_size for f in manifest.files.values()
    )
    arrays = container.open_arrays(tmp_path / "db")
    assert "big" in arrays and "nope" not in arrays and sorted(arrays) == sorted(_arrays())
    assert _mapped(arrays["big"]) and not _mapped(arrays["small"])
    for name, value in _arrays().items():
        assert arrays[name].dtype == value.dtype and np.array_equal(arrays[name], value)
    arrays["big"][0] = -1.0  # private to this process
    assert container.load_all(tmp_path / "db")["big"][0] == 0.0
    with open_database(tmp_path / "db") as lazy:
        assert list(lazy["library.names"]) == ["a", "b"]


def test_legacy_npz_still_opens(tmp_path: Path) -> None:
    np.savez(tmp_path / "data.npz", **_arrays())
    for path in (tmp_path / "data.npz", tmp_path):
        with open_database(path) as arrays:
            assert np.array_equal(arrays["small"], _arrays()["small"])


def test_incomplete_or_forged_directories_are_refused(tmp_path: Path) -> None:
    (tmp_path / "arrays").mkdir()
    with pytest.raises(container.ContainerError, match="holds no database arrays"):
        container.open_arrays(tmp_path)  # no manifest: a write that did not finish
    doc = {"format": container.FORMAT, "arrays": {"x": {"file": "../../etc/passwd", "bytes": 1}}}
    (tmp_path / container.MANIFEST).write_text(json.dumps(doc))
    with pytest.raises(container.ContainerError, match="invalid file"):
        container.open_arrays(tmp_path)
    (tmp_path / container.MANIFEST).write_text(json.dumps({"format": "other/9", "arrays": {}}))
    with pytest.raises(container.ContainerError, match="unknown database format"):
        container.open_arrays(tmp_path)
    with pytest.raises(ValueError, match="pickle"):
        container.npy_bytes(np.array([object()]))
