"""Reading a user's glTF 2.0 file (GLB, or ``.gltf`` with its buffers) as one document and one
binary buffer, so that data can be added to it and the whole written back as a GLB.

A ``.gltf`` file's buffers (``data:`` URIs or files beside it) are concatenated into the one
binary buffer a GLB holds, each starting on a 4-byte boundary, and its buffer views are moved
accordingly; images keep their URIs (a ``.gltf`` whose textures are files needs them beside the
output too). A GLB whose extra buffers point to files is read the same way.
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path
from typing import Any

from ..errors import ExportError

CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942


def read_gltf(raw: bytes, base_dir: str | Path | None = None) -> tuple[dict[str, Any], bytearray]:
    """The document and its single binary buffer (``buffers`` is ``[{"byteLength": n}]`` after,
    or absent for a file without binary data).

    Parameters
    ----------
    raw:
        The file's bytes: a GLB container or a ``.gltf`` JSON text.
    base_dir:
        Where relative buffer URIs are read from (the file's folder).

    Raises
    ------
    ExportError
        For a file that is not glTF, or a buffer that cannot be read.
    """
    glb_bin: bytes | None = None
    try:
        if raw[:4] == b"glTF":
            length, kind = struct.unpack_from("<II", raw, 12)
            if kind != CHUNK_JSON:
                raise ExportError("the GLB's first chunk is not JSON")
            doc = json.loads(raw[20 : 20 + length])
            at = 20 + length
            if len(raw) >= at + 8:
                blen, bkind = struct.unpack_from("<II", raw, at)
                if bkind == CHUNK_BIN:
                    glb_bin = raw[at + 8 : at + 8 + blen]
        else:
            doc = json.loads(raw)
    except (ValueError, struct.error) as exc:
        raise ExportError(f"not a glTF/GLB file: {exc}") from None
    if not isinstance(doc, dict):
        raise ExportError("not a glTF document (its JSON is not an object)")
    data = bytearray()
    starts: list[int] = []
    for k, buf in enumerate(doc.get("buffers", [])):
        data.extend(b"\0" * (-len(data) % 4))
        starts.append(len(data))
        data.extend(_buffer(buf, k, glb_bin, base_dir))
    for view in doc.get("bufferViews", []):
        view["byteOffset"] = starts[int(view.get("buffer", 0))] + int(view.get("byteOffset", 0))
        view["buffer"] = 0
    if doc.get("buffers"):
        doc["buffers"] = [{"byteLength": len(data)}]
    return doc, data


def _buffer(buf: dict[str, Any], index: int, glb_bin: bytes | None, base_dir: str | Path | None) -> bytes:
    uri = buf.get("uri")
    size = int(buf.get("byteLength", 0))
    if uri is None:
        if index != 0 or glb_bin is None:
            raise ExportError(f"buffer {index} has no data (no URI and no GLB binary chunk)")
        return bytes(glb_bin[:size])
    if uri.startswith("data:"):
        try:
            return base64.b64decode(uri.split(",", 1)[1])[:size]
        except (IndexError, ValueError) as exc:
            raise ExportError(f"buffer {index}: bad data URI: {exc}") from None
    path = Path(base_dir or ".") / str(uri)
    try:
        return path.read_bytes()[:size]
    except OSError as exc:
        raise ExportError(f"buffer {index}: cannot read {path}: {exc.strerror or exc}") from None
