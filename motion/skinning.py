"""A glTF character's skinned mesh, and linear-blend skinning of it on a motion (numpy).

:func:`read_skinned_mesh` reads every mesh primitive bound to a glTF/GLB file's first skin (the
skin :func:`motion.retarget.character.gltf_character` reads the skeleton of): rest vertex
positions, the joints and weights of each vertex (``JOINTS_n``/``WEIGHTS_n``, every set), and each
joint's bind transform (the inverse of the skin's inverse bind matrix; the rest world transform of
its node when the file has none). :func:`skin` deforms those vertices the way glTF viewers and DCC
tools do, by linear blend skinning:

``v(t) = sum_k w_k M_k(t) B_k^-1 v``

with ``M_k(t)`` joint ``k``'s world transform in frame ``t`` and ``B_k`` its bind transform. A
motion's joints carry rotations and positions only (no scale: a parent ``Armature`` node's 0.01
scale is in the bind transforms), so ``M_k(t) B_k^-1`` is the rigid motion taking the joint's
bind frame onto its frame ``t``: ``p_k(t) + R_k(t) R_bk^T (v - p_bk)`` with ``R_bk`` the rotation
of ``B_k`` (its polar part) and ``p_bk`` its origin. The vertices of a skinned mesh are in the
skeleton's bind space: glTF ignores the mesh node's own transform.

Everything is in metres, Y up (glTF's convention and Segue's).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from . import rotations as rot
from .errors import MotionError
from .gltf_file import GltfFile
from .motion import Motion

Array = npt.NDArray[np.float64]

__all__ = ["BoundMesh", "animation_pose", "read_skinned_mesh", "skin", "skin_motion"]


@dataclass(frozen=True)
class BoundMesh:
    """The skinned mesh of a character, in its bind pose.

    Attributes
    ----------
    vertices:
        ``(V, 3)`` rest (bind-space) vertex positions, metres.
    joints:
        ``(V, K)`` the character joint each weight belongs to (indices into ``names``).
    weights:
        ``(V, K)`` non-negative weights, each row summing to 1.
    names:
        The skin's joint names, in the order ``joints`` indexes.
    bind_rotations, bind_positions:
        ``(J, 4)`` and ``(J, 3)``: each joint's bind transform (rotation, metres), the inverse of
        its inverse bind matrix (scale removed).
    """

    vertices: Array
    joints: npt.NDArray[np.intp]
    weights: Array
    names: tuple[str, ...]
    bind_rotations: Array
    bind_positions: Array

    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    def reindexed(self, names: tuple[str, ...]) -> BoundMesh:
        """The same mesh with joints indexed by ``names`` (a character skeleton's order); every
        skin joint must be there."""
        where = {n: i for i, n in enumerate(names)}
        missing = [n for n in self.names if n not in where]
        if missing:
            raise MotionError(f"the skinned mesh's joints are not the skeleton's (missing: {missing[:5]})")
        order = np.array([where[n] for n in self.names], dtype=np.intp)
        rots = np.tile(rot.IDENTITY, (len(names), 1))
        pos = np.zeros((len(names), 3))
        rots[order], pos[order] = self.bind_rotations, self.bind_positions
        return BoundMesh(self.vertices, order[self.joints], self.weights, names, rots, pos)


def read_skinned_mesh(raw: bytes, base_dir: str | Path | None = None) -> BoundMesh | None:
    """The mesh primitives bound to the first skin of a glTF/GLB file, as one
    :class:`BoundMesh` (triangles are not needed: only vertices touch the floor); ``None`` when
    no mesh is bound to that skin or its primitives have no ``JOINTS_0``/``WEIGHTS_0``.

    Raises :class:`MotionError` for a file that is not glTF or whose skin data is malformed."""
    gltf = GltfFile.read(raw, base_dir, source="character")
    doc = gltf.doc
    try:
        skins = doc.get("skins") or []
        if not skins or not skins[0].get("joints"):
            return None
        nodes = doc.get("nodes", [])
        joints = [int(j) for j in skins[0]["joints"]]
        names = tuple(str(nodes[j].get("name") or f"joint{j}") for j in joints)
        if "inverseBindMatrices" in skins[0]:
            ibm = gltf.accessor(int(skins[0]["inverseBindMatrices"])).reshape(-1, 4, 4)
            bind = np.linalg.inv(np.swapaxes(ibm, 1, 2))  # column-major
        else:
            world = gltf.world_matrices(joints)
            bind = np.array([world[j] for j in joints])
        if bind.shape[0] != len(joints):
            raise MotionError("the skin's inverse bind matrices do not match its joints")
        verts, vj, vw = [], [], []
        for node in nodes:
            if int(node.get("skin", -1)) != 0 or "mesh" not in node:
                continue
            for prim in doc["meshes"][int(node["mesh"])].get("primitives", []):
                attrs = prim.get("attributes", {})
                if "POSITION" not in attrs or "JOINTS_0" not in attrs or "WEIGHTS_0" not in attrs:
                    continue
                verts.append(gltf.accessor(attrs["POSITION"]))
                sets = sorted(int(k.split("_")[1]) for k in attrs if k.startswith("JOINTS_"))
                vj.append(np.concatenate([gltf.accessor(attrs[f"JOINTS_{s}"]) for s in sets], axis=1))
                vw.append(np.concatenate([gltf.accessor(attrs[f"WEIGHTS_{s}"]) for s in sets], axis=1))
    except (IndexError, KeyError, TypeError, ValueError) as exc:
        raise MotionError(f"malformed glTF skin or mesh: {exc}") from None
    if not verts:
        return None
    width = max(j.shape[1] for j in vj)
    j_all = np.concatenate([np.pad(j, ((0, 0), (0, width - j.shape[1]))) for j in vj]).astype(np.intp)
    w_all = np.maximum(np.concatenate([np.pad(w, ((0, 0), (0, width - w.shape[1]))) for w in vw]), 0.0)
    if j_all.size and (j_all.min() < 0 or j_all.max() >= len(joints)):
        raise MotionError("a vertex of the skinned mesh names a joint the skin does not have")
    total = w_all.sum(axis=1, keepdims=True)
    keep = total[:, 0] > 0  # a vertex with no weight does not follow the skeleton
    w_all = w_all[keep] / total[keep]
    lin = bind[:, :3, :3]
    u, _, vt = np.linalg.svd(lin)
    polar = u @ vt
    return BoundMesh(
        np.concatenate(verts)[keep],
        j_all[keep],
        w_all,
        names,
        rot.normalize(rot.from_matrix(polar)),
        np.asarray(bind[:, :3, 3], dtype=np.float64).copy(),
    )


def skin(
    mesh: BoundMesh, positions: Array, rotations: Array, vertices: npt.NDArray[np.intp] | None = None
) -> Array:
    """``(F, V, 3)`` the mesh's vertices (or those indexed by ``vertices``) deformed by linear
    blend skinning (module docstring), metres.

    ``positions (F, J, 3)`` metres and ``rotations (F, J, 4)``: the world positions and rotations
    of the skeleton's joints, in the order ``mesh.joints`` indexes (:meth:`BoundMesh.reindexed`).
    """
    sel = slice(None) if vertices is None else vertices
    v = mesh.vertices[sel]
    js, ws = mesh.joints[sel], mesh.weights[sel]
    out = np.zeros((positions.shape[0], v.shape[0], 3))
    for k in range(js.shape[1]):
        w = ws[:, k]
        used = w > 0
        if not used.any():
            continue
        j = js[used, k]
        local = rot.rotate(rot.inverse(mesh.bind_rotations[j]), v[used] - mesh.bind_positions[j])  # (U, 3)
        world = positions[:, j] + rot.rotate(
            rotations[:, j], np.broadcast_to(local, (positions.shape[0], *local.shape))
        )
        out[:, used] += w[used, None] * world
    return out


def skin_motion(mesh: BoundMesh, motion: Motion, vertices: npt.NDArray[np.intp] | None = None) -> Array:
    """:func:`skin` on ``motion`` (a character in its own joints: the skin's joint names, any
    units, converted to metres)."""
    m = mesh.reindexed(motion.skeleton.names)
    pos, grot = motion.fk()
    return skin(m, pos * motion.metres_per_unit, grot, vertices)


def _interpolate(times: Array, keys: Array, values: Array, rotation: bool) -> Array:
    """``values (K, W)`` keyed at ``keys (K,)`` sampled at ``times (T,)`` (LINEAR: lerp, or slerp
    for rotations; held before the first key and after the last)."""
    if keys.size == 1:
        return np.repeat(values[:1], times.size, axis=0)
    i = np.clip(np.searchsorted(keys, times, side="right") - 1, 0, keys.size - 2)
    span = np.maximum(keys[i + 1] - keys[i], 1e-12)
    t = np.clip((times - keys[i]) / span, 0.0, 1.0)
    if rotation:
        return np.asarray(rot.slerp(rot.normalize(values[i]), rot.normalize(values[i + 1]), t))
    return np.asarray(values[i] + t[:, None] * (values[i + 1] - values[i]))


def animation_pose(
    raw: bytes, animation: int = -1, base_dir: str | Path | None = None
) -> tuple[tuple[str, ...], Array, Array, Array]:
    """The first skin's joints posed by one animation of a glTF/GLB file, as a viewer plays it.

    Returns the joint names, ``positions (F, J, 3)`` (metres) and ``rotations (F, J, 4)`` of the
    joints in the world (nodes above the skin included, their scale in the bind transforms) at
    the animation's key times ``times (F,)`` (the sampler input with the most keys, seconds); other
    channels are interpolated there (LINEAR; STEP and CUBICSPLINE samplers are refused)."""
    gltf = GltfFile.read(raw, base_dir, source="character")
    doc = gltf.doc
    try:
        anim = doc["animations"][animation]
        nodes = doc["nodes"]
        inputs = {int(s["input"]) for s in anim["samplers"]}
        main = max(inputs, key=lambda a: int(doc["accessors"][a]["count"]))
        times = gltf.accessor(main)[:, 0]
        count = times.size
        trs = []
        for i in range(len(nodes)):
            t, q, scale = gltf.local(i)
            trs.append([np.tile(t, (count, 1)), np.tile(q, (count, 1)), scale])
        for ch in anim["channels"]:
            sampler = anim["samplers"][int(ch["sampler"])]
            if sampler.get("interpolation", "LINEAR") != "LINEAR":
                raise MotionError(f"{sampler['interpolation']} animation samplers are not read here")
            path = ch["target"]["path"]
            if path not in ("translation", "rotation"):
                continue
            keys = gltf.accessor(int(sampler["input"]))[:, 0]
            values = gltf.accessor(int(sampler["output"]))
            trs[int(ch["target"]["node"])][0 if path == "translation" else 1] = _interpolate(
                times, keys, values, path == "rotation"
            )
        parent = {int(c): i for i, nd in enumerate(nodes) for c in nd.get("children", [])}
        world: dict[int, Array] = {}

        def of(i: int) -> Array:
            if i not in world:
                t, q, s = trs[i]
                m = np.tile(np.eye(4), (count, 1, 1))
                m[:, :3, :3] = rot.to_matrix(rot.normalize(q)) * s
                m[:, :3, 3] = t
                world[i] = of(parent[i]) @ m if i in parent else m
            return world[i]

        joints = [int(j) for j in doc["skins"][0]["joints"]]
        mats = np.stack([of(j) for j in joints], axis=1)  # (F, J, 4, 4)
        names = tuple(str(nodes[j].get("name") or f"joint{j}") for j in joints)
    except (IndexError, KeyError, TypeError, ValueError) as exc:
        raise MotionError(f"malformed glTF animation: {exc}") from None
    u, _, vt = np.linalg.svd(mats[..., :3, :3])
    rotations = rot.normalize(rot.from_matrix(u @ vt))
    return names, mats[..., :3, 3].copy(), np.asarray(rotations), times
