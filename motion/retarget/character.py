"""Reading a character: a BVH skeleton or a glTF/GLB skin, and its rest pose.

A character is returned as a one-frame :class:`~motion.motion.Motion` whose frame is the rest
pose. BVH: the rest pose is the file's first frame (``rest="first"``, a character exported from a
DCC tool in its bind pose) or the zero-rotation pose of its offsets (``rest="zero"``); its units
are guessed from its height as for any BVH (:mod:`motion.units`). glTF/GLB: the skin's joints
(``skins[0]``), their hierarchy and their rest (bind) pose from the nodes' translation, rotation and
scale (a parent ``Armature`` node's transform, e.g. a 0.01 scale, is applied); the character is in
metres, and its BVH offsets are the bind pose's bone vectors in the parent's frame.

The glTF file is read by :mod:`motion.gltf_file` (the JSON chunk and node transforms only: no
buffers or accessors are needed to know a skeleton's bind pose).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from .. import rotations as rot
from ..bvh import BvhLimits
from ..errors import MotionError
from ..gltf_file import GltfFile, gltf_json
from ..io import load_motion
from ..motion import Motion
from ..skeleton import Skeleton, default_channels
from .transfer import zero_pose

Array = npt.NDArray[np.float64]
REST_POSES = ("first", "zero")
GLTF_SUFFIXES = (".glb", ".gltf")


def load_character(
    path: str | Path, *, rest: str = "first", units: str | None = None, limits: BvhLimits | None = None
) -> Motion:
    """The character in ``path`` (BVH, ``sample:NAME``, ``.glb`` or ``.gltf``) as a one-frame
    motion in its rest pose (module docstring). ``units`` declares a BVH's unit."""
    if rest not in REST_POSES:
        raise MotionError(f"rest pose {rest!r}: use one of {', '.join(REST_POSES)}")
    p = Path(str(path))
    if p.name.lower().endswith(GLTF_SUFFIXES):
        try:
            raw = p.read_bytes()
        except OSError as exc:
            raise MotionError(f"{p}: cannot read the character: {exc.strerror or exc}") from None
        return gltf_character(raw, name=p.stem)
    motion = load_motion(path, units=units, limits=limits)
    return zero_pose(motion) if rest == "zero" else motion.slice(0, 1)


def gltf_character(raw: bytes, name: str = "character") -> Motion:
    """The first skin of a glTF/GLB document as a one-frame motion in its bind pose (metres)."""
    gltf = GltfFile.json_only(raw, source=name)
    doc, nodes = gltf.doc, gltf.nodes
    skins = doc.get("skins", [])
    if not skins or not skins[0].get("joints"):
        raise MotionError("the glTF file has no skin with joints: a character needs a skinned skeleton")
    try:
        joints = [int(j) for j in skins[0]["joints"]]
        order, parents = gltf.skin_tree(joints)
        world = gltf.world_matrices(order)
        mats = [world[i] for i in order]
    except (IndexError, KeyError, TypeError, ValueError, RecursionError) as exc:
        raise MotionError(f"malformed glTF node hierarchy: {exc}") from None
    pos = np.array([m[:3, 3] for m in mats])
    rots = []
    for m in mats:
        lin = m[:3, :3]
        u, _, vt = np.linalg.svd(lin)
        r = u @ vt
        if np.linalg.det(r) < 0:
            raise MotionError("a skin joint is mirrored (negative scale), which BVH cannot hold")
        rots.append(rot.from_matrix(r))
    g = np.array(rots)
    names = [str(nodes[i].get("name") or f"joint{i}") for i in order]
    if len(set(names)) != len(names):
        raise MotionError("the skin's joint names are not unique")
    par = np.array(parents, dtype=np.intp)
    offsets = np.zeros((len(order), 3))
    local = np.tile(rot.IDENTITY, (len(order), 1))
    for k, pk in enumerate(par):
        if pk < 0:
            offsets[k], local[k] = pos[k], g[k]
        else:
            inv = rot.inverse(g[pk])
            offsets[k] = rot.rotate(inv, pos[k] - pos[pk])
            local[k] = rot.multiply(inv, g[k])
    if not np.all(np.isfinite(offsets)):
        raise MotionError("the skin's bind pose is not finite")
    skeleton = Skeleton(tuple(names), par, offsets, default_channels(len(names)))
    return Motion(skeleton, offsets[:1].copy(), local[None], 30.0, units="m", name=name)


def gltf_timing(raw: bytes) -> tuple[int, float] | None:
    """``(frames, fps)`` of a glTF/GLB document's first animation (its first sampler's keyframe
    times: the accessor's count, min and max, which glTF requires), None when it has none."""
    doc = gltf_json(raw)
    try:
        anims = doc.get("animations") or []
        if not anims or not anims[0].get("samplers"):
            return None
        acc = doc["accessors"][int(anims[0]["samplers"][0]["input"])]
        count = int(acc["count"])
        span = float(acc["max"][0]) - float(acc["min"][0])
    except (IndexError, KeyError, TypeError, ValueError) as exc:
        raise MotionError(f"malformed glTF animation: {exc}") from None
    fps = (count - 1) / span if count > 1 and span > 0 else 0.0
    return count, float(round(fps)) if abs(fps - round(fps)) < 1e-4 * fps else fps
