"""A built database's arrays on disk: one uncompressed ``.npy`` per array plus a manifest.

Layout of a database directory (the store keeps the same layout as objects, see
:mod:`workers.store`)::

    arrays.json          {"format": "segue-npy/1", "arrays": {name: {"file", "bytes"}}, "bytes": total}
    arrays/<file>.npy    one array each (numpy's .npy format, never pickle)

Why ``.npy`` files and not zarr or the ``.npz`` the store used before: an uncompressed ``.npy`` is a
short header and the raw array, so :func:`open_arrays` memory-maps it (``mmap_mode="c"``) and loading a
database costs its metadata. The pages come from the OS page cache, which every engine process on a
host shares; an engine that writes into an array gets private copies of the pages it touches (copy
on write), never a change on disk. zarr would add chunking and compression we do not want for
arrays that are read whole, and a dependency; ``.npz`` members cannot be mapped (zip). The manifest is
written last: a directory without one is incomplete (a crashed write or download) and is not read.

Small arrays (below :data:`MMAP_MIN_BYTES`) are read into memory: a map per scalar would cost more
than it saves.
"""

from __future__ import annotations

import io
import json
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

FORMAT = "segue-npy/1"
MANIFEST = "arrays.json"
ARRAYS_DIR = "arrays"
MMAP_MIN_BYTES = 64 << 10
"""Arrays of at least this many bytes are memory-mapped; smaller ones are read."""

_SAFE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._\-]{0,120}$")


class ContainerError(ValueError):
    """A database directory or manifest that cannot be read."""


@dataclass(frozen=True, slots=True)
class Manifest:
    """A database's array names, their files (relative to ``arrays/``) and sizes in bytes."""

    files: dict[str, str]
    sizes: dict[str, int]

    @property
    def total_bytes(self) -> int:
        """Bytes of every array file (what a memory map of the database spans)."""
        return sum(self.sizes.values())

    def to_bytes(self) -> bytes:
        arrays = {n: {"file": self.files[n], "bytes": self.sizes[n]} for n in self.files}
        return json.dumps({"format": FORMAT, "arrays": arrays, "bytes": self.total_bytes}).encode()

    @classmethod
    def from_bytes(cls, data: bytes) -> Manifest:
        try:
            doc = json.loads(data)
            if doc.get("format") != FORMAT:
                raise ContainerError(f"unknown database format {doc.get('format')!r}")
            files = {str(n): str(a["file"]) for n, a in doc["arrays"].items()}
            sizes = {str(n): int(a["bytes"]) for n, a in doc["arrays"].items()}
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ContainerError(f"unreadable database manifest: {exc}") from None
        if any(not _SAFE.match(f) or not f.endswith(".npy") for f in files.values()):
            raise ContainerError("database manifest names an invalid file")
        return cls(files, sizes)


def npy_bytes(array: npt.ArrayLike) -> bytes:
    """One array in the ``.npy`` format (no pickle: object arrays are refused)."""
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(array), allow_pickle=False)
    return buf.getvalue()


def array_from_npy(data: bytes) -> npt.NDArray[Any]:
    """The array held by ``.npy`` bytes."""
    return np.asarray(np.load(io.BytesIO(data), allow_pickle=False))


def pack(arrays: Mapping[str, npt.ArrayLike]) -> tuple[Manifest, list[tuple[str, bytes]]]:
    """The manifest and the ``(file, .npy bytes)`` of each array, for a writer to store (the
    manifest last)."""
    files: dict[str, str] = {}
    sizes: dict[str, int] = {}
    out: list[tuple[str, bytes]] = []
    for i, (name, array) in enumerate(arrays.items()):
        file = f"{name}.npy" if _SAFE.match(name) and name not in (".", "..") else f"a{i:05d}.npy"
        if file in files.values():
            file = f"a{i:05d}.npy"
        data = npy_bytes(array)
        files[name], sizes[name] = file, len(data)
        out.append((file, data))
    return Manifest(files, sizes), out


def write_dir(path: str | Path, arrays: Mapping[str, npt.ArrayLike]) -> Manifest:
    """Write a database directory (arrays first, the manifest last)."""
    root = Path(path)
    (root / ARRAYS_DIR).mkdir(parents=True, exist_ok=True)
    manifest, files = pack(arrays)
    for file, data in files:
        (root / ARRAYS_DIR / file).write_bytes(data)
    (root / MANIFEST).write_bytes(manifest.to_bytes())
    return manifest


def read_manifest(path: str | Path) -> Manifest:
    """The manifest of a database directory (``ContainerError`` when there is none)."""
    try:
        return Manifest.from_bytes((Path(path) / MANIFEST).read_bytes())
    except FileNotFoundError:
        raise ContainerError(f"{path} holds no database arrays ({MANIFEST})") from None


def load_npy(path: Path, size: int | None = None) -> npt.NDArray[Any]:
    """One ``.npy`` file: memory-mapped copy-on-write when large, else read."""
    if size is None:
        size = path.stat().st_size
    if size >= MMAP_MIN_BYTES:
        mapped = np.load(path, mmap_mode="c", allow_pickle=False)
        return np.asarray(mapped).view(np.ndarray)
    return np.asarray(np.load(path, allow_pickle=False))


def read_only(array: npt.ArrayLike) -> npt.NDArray[Any]:
    """A read-only view of an array (no copy): what an engine keeps of a loaded database's arrays,
    so that its memory-mapped pages are never written (a write would give the process a private
    copy of the page, and change what every reader of that array in the process sees)."""
    view = np.asarray(array).view()
    view.flags.writeable = False
    return view


class LazyArrays(Mapping[str, npt.NDArray[Any]]):
    """A database's arrays by name, each fetched by ``load(name)`` when first indexed (then kept)."""

    def __init__(self, manifest: Manifest, load: Callable[[str], npt.NDArray[Any]]) -> None:
        self.manifest = manifest
        self._load = load
        self._loaded: dict[str, npt.NDArray[Any]] = {}

    def __getitem__(self, name: str) -> npt.NDArray[Any]:
        if name not in self.manifest.files:
            raise KeyError(name)
        if name not in self._loaded:
            self._loaded[name] = self._load(name)
        return self._loaded[name]

    def __contains__(self, name: object) -> bool:
        return name in self.manifest.files  # without reading the array

    def __iter__(self) -> Iterator[str]:
        return iter(self.manifest.files)

    def __len__(self) -> int:
        return len(self.manifest.files)

    @property
    def files(self) -> list[str]:
        """The array names (as ``numpy.lib.npyio.NpzFile.files``)."""
        return list(self.manifest.files)


def open_arrays(path: str | Path) -> LazyArrays:
    """The arrays of a database directory, each memory-mapped (or read, when small) on first use."""
    root = Path(path)
    manifest = read_manifest(root)

    def load(name: str) -> npt.NDArray[Any]:
        return load_npy(root / ARRAYS_DIR / manifest.files[name], manifest.sizes[name])

    return LazyArrays(manifest, load)


def load_all(path: str | Path) -> dict[str, npt.NDArray[Any]]:
    """Every array of a database directory (large ones memory-mapped), as a dict for ``Engine.load``."""
    arrays = open_arrays(path)
    return {name: arrays[name] for name in arrays}
