"""A result bound to the artist's armature: each bone's pose, exactly, from the GLB Segue returns.

Segue answers ``GET /v1/jobs/{id}/result?format=glb&character=<the rig's GLB>`` with the rig's own
skeleton animated (node transforms in each node's parent space, glTF axes). Blender's glTF
importer may give bones other rest orientations than the rig's (its bone-direction heuristics),
so the add-on never imports it: it evaluates the animated world matrix ``G_n(t)`` of each joint
node and maps it onto the bone with the rest correspondence it exported. With ``R_n`` the node's
rest world matrix (glTF), ``C`` Blender-to-glTF axes, ``W`` the armature object's world matrix,
``b_n`` the bone's rest matrix (``Bone.matrix_local``) and ``X`` where the result's origin sits in
Blender's world, the bone's pose (armature space, ``PoseBone.matrix``) is::

    pose_n(t) = W^-1 X C^-1 . G_n(t) . R_n^-1 C W b_n

whatever axes the exporter gave the node (``R_n = C W b_n K_n`` for some constant ``K_n``, which
cancels). Blender's own ``Bone.convert_local_to_pose`` turns that into the keyed
``matrix_basis`` (inherit-scale and local-location options included); :func:`basis_matrices` is
the plain formula, for tests and bones with the default options.

The matrix arithmetic goes through a :class:`MatrixOps` (``mathutils`` inside Blender: fast;
:class:`PlainOps` here: plain Python, for tests), so that one code path does both.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol, TypeVar

from . import gltf, mat4
from .axes import BLENDER_FROM_GLTF, GLTF_FROM_BLENDER
from .mat4 import Mat4

M = TypeVar("M")


class MatrixOps(Protocol[M]):
    """Matrix arithmetic on some matrix type ``M``."""

    def matrix(self, m: Mat4) -> M:
        """``m`` (16 floats, row major) as an ``M``."""
        ...

    def trs(self, t: Sequence[float], q: Sequence[float], s: Sequence[float]) -> M:
        """Translation, rotation ``(x, y, z, w)``, scale as an ``M`` (``T R S``)."""
        ...

    def mul(self, a: M, b: M) -> M:
        """``a @ b``."""
        ...


class PlainOps:
    """:class:`MatrixOps` on :mod:`.mat4` tuples."""

    def matrix(self, m: Mat4) -> Mat4:
        return m

    def trs(self, t: Sequence[float], q: Sequence[float], s: Sequence[float]) -> Mat4:
        return mat4.from_trs(t, q, s)

    def mul(self, a: Mat4, b: Mat4) -> Mat4:
        return mat4.mul(a, b)


@dataclass(frozen=True, slots=True)
class RestBone:
    """A bone of the armature: its name, parent's name and rest matrix (armature space)."""

    name: str
    parent: str | None
    matrix_local: Mat4


class BindingError(ValueError):
    """A GLB that does not bind to the armature (no skin, a joint naming no bone...)."""


@dataclass(slots=True)
class Binding:
    """What evaluating a bound GLB on an armature needs (:func:`plan`).

    ``order``: the nodes evaluated, each after its parent; ``parent``/``rest_local``/``base``: each
    one's parent (None above the evaluated ones), rest local matrix and, for a top node, its
    parent's rest world matrix; ``bone``: joint node -> the bone it drives; ``left``, ``right``:
    the constant factors of the module docstring's formula; ``times``: the animation's key times
    (seconds)."""

    order: list[int]
    parent: dict[int, int | None]
    rest_local: dict[int, Mat4]
    base: dict[int, Mat4]
    bone: dict[int, str]
    left: Mat4
    right: dict[int, Mat4]
    animation: gltf.Animation
    nodes: list[gltf.Node]

    @property
    def times(self) -> list[float]:
        return self.animation.times or [0.0]


def plan(
    raw: bytes,
    bone_of: Mapping[str, str],
    rest: Mapping[str, RestBone],
    armature_world: Mat4,
    placement: Mat4 = mat4.IDENTITY,
) -> Binding:
    """The binding of a bound GLB (``raw``: Segue's ``character=`` download, whole or
    ``animation_only``) to an armature.

    Parameters
    ----------
    bone_of:
        GLB joint (node) name -> bone name (the inverse of the names the rig was uploaded under).
    rest:
        The armature's bones by name.
    armature_world:
        The armature object's world matrix (Blender) when the rig was exported.
    placement:
        Where the result's origin sits in Blender's world (:meth:`.axes.SegueFrame.placement`).
    """
    doc, binary = gltf.split_glb(raw)
    nodes = gltf.nodes_of(doc)
    try:
        joints = gltf.skin_joints(doc)
        anim = gltf.animation(doc, binary)
    except gltf.GltfError as exc:
        raise BindingError(f"the result does not bind: {exc}") from None
    world = gltf.rest_world(nodes)
    bone: dict[int, str] = {}
    unknown = []
    for n in joints:
        name = bone_of.get(nodes[n].name)
        if name is None or name not in rest:
            unknown.append(nodes[n].name)
        else:
            bone[n] = name
    if unknown:
        raise BindingError(f"the result's joints {unknown[:5]} are not bones of the armature")
    needed: set[int] = set()
    for n in joints:
        i: int | None = n
        while i is not None and i not in needed:
            needed.add(i)
            i = nodes[i].parent
    order: list[int] = []
    placed: set[int] = set()

    def visit(i: int) -> None:
        p = nodes[i].parent
        if p is not None and p in needed and p not in placed:
            visit(p)
        if i not in placed:
            placed.add(i)
            order.append(i)

    for i in sorted(needed):
        visit(i)
    parent = {i: (nodes[i].parent if nodes[i].parent in needed else None) for i in order}
    base = {i: mat4.IDENTITY for i in order if parent[i] is None}
    left = mat4.mul(mat4.inverse(armature_world), mat4.mul(placement, BLENDER_FROM_GLTF))
    cw = mat4.mul(GLTF_FROM_BLENDER, armature_world)
    right = {n: mat4.mul(mat4.inverse(world[n]), mat4.mul(cw, rest[b].matrix_local)) for n, b in bone.items()}
    return Binding(order, parent, {i: nodes[i].matrix() for i in order}, base, bone, left, right, anim, nodes)


def pose_matrices(
    binding: Binding, ops: MatrixOps[M], times: Sequence[float] | None = None
) -> dict[str, list[M]]:
    """Bone name -> its pose matrix (armature space) at each time (default: the animation's key
    times), in ``ops``'s matrix type."""
    anim = binding.animation
    ts = list(binding.times if times is None else times)
    left = ops.matrix(binding.left)
    right = {n: ops.matrix(m) for n, m in binding.right.items()}
    base = {n: ops.matrix(m) for n, m in binding.base.items()}
    rest_m = {n: ops.matrix(m) for n, m in binding.rest_local.items()}
    out: dict[str, list[M]] = {b: [] for b in binding.bone.values()}
    nodes = binding.nodes
    for t in ts:
        world: dict[int, M] = {}
        for i in binding.order:
            ch = anim.channels.get(i)
            if ch:
                nd = nodes[i]
                tr = ch["translation"].at(t) if "translation" in ch else nd.translation
                ro = ch["rotation"].at(t, rotation=True) if "rotation" in ch else nd.rotation
                sc = ch["scale"].at(t) if "scale" in ch else nd.scale
                local = ops.trs(tr, ro, sc)
            else:
                local = rest_m[i]
            p = binding.parent[i]
            world[i] = ops.mul(world[p] if p is not None else base[i], local)
        for n, b in binding.bone.items():
            out[b].append(ops.mul(ops.mul(left, world[n]), right[n]))
    return out


def basis_matrices(
    poses: Mapping[str, Sequence[Mat4]], rest: Mapping[str, RestBone]
) -> dict[str, list[Mat4]]:
    """Each posed bone's ``matrix_basis`` from its pose and its parent's (default bone options:
    inherit rotation and full scale, local location); a parent without a pose is at rest."""
    out: dict[str, list[Mat4]] = {}
    cache: dict[str, list[Mat4]] = {}

    def pose_of(name: str, frames: int) -> list[Mat4]:
        if name in poses:
            return list(poses[name])
        if name not in cache:
            b = rest[name]
            if b.parent is None:
                cache[name] = [b.matrix_local] * frames
            else:
                rel = mat4.mul(mat4.inverse(rest[b.parent].matrix_local), b.matrix_local)
                cache[name] = [mat4.mul(p, rel) for p in pose_of(b.parent, frames)]
        return cache[name]

    for name, seq in poses.items():
        b = rest[name]
        if b.parent is None:
            inv = mat4.inverse(b.matrix_local)
            out[name] = [mat4.mul(inv, p) for p in seq]
            continue
        rel_inv = mat4.inverse(mat4.mul(mat4.inverse(rest[b.parent].matrix_local), b.matrix_local))
        parents = pose_of(b.parent, len(seq))
        out[name] = [
            mat4.mul(rel_inv, mat4.mul(mat4.inverse(pp), p)) for pp, p in zip(parents, seq, strict=True)
        ]
    return out


__all__ = [
    "Binding",
    "BindingError",
    "MatrixOps",
    "PlainOps",
    "RestBone",
    "basis_matrices",
    "plan",
    "pose_matrices",
]
