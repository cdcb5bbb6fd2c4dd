"""Segue's mannequin: a skinned body for any skeleton, and that body as a character GLB.

Animators judge motion on a body, not on lines. Segue ships no character (no outside assets), so
it makes one from the skeleton it is given (:mod:`motion.export.body`: a smooth shape per body
part skinned to its bones, soles flat on the rest floor). The browser shows results on it when the
user has chosen no character of their own, and tests build characters with it: any skeleton,
under any joint names, becomes a skinned character file that :func:`segue retarget --to
<motion.retarget.character.gltf_character>` and Blender read like an artist's rig.

Example
-------
>>> from motion.io import load_motion
>>> from motion.export.mannequin import mannequin_glb, mannequin_mesh
>>> walk = load_motion("sample:walk")
>>> body = mannequin_mesh(walk)
>>> body.positions.shape[1], bool(abs(body.weights.sum(axis=1) - 1).max() < 1e-6)
(3, True)
>>> mannequin_glb(walk)[:4]
b'glTF'
"""

from __future__ import annotations

from collections.abc import Sequence

from ..motion import Motion
from .body import SkinnedMesh, body_mesh
from .glb import glb_bytes

__all__ = ["SkinnedMesh", "mannequin_glb", "mannequin_mesh"]


def mannequin_mesh(rest: Motion, frame: int = 0) -> SkinnedMesh:
    """The mannequin of ``rest``'s skeleton in its pose at ``frame``, in metres.

    Parameters
    ----------
    rest:
        A motion whose ``frame`` is the pose to build the body on (the character's rest pose:
        standing, T- or A-pose), lengths in ``rest.units``.
    frame:
        The frame of ``rest`` to use.

    Returns
    -------
    The body in that pose (world positions of the frame, metres), its floor the pose's lowest
    joint or End Site.
    """
    pose = rest.slice(frame, frame + 1)
    pos, grot = pose.fk()
    scale = pose.metres_per_unit
    ends = pose.end_site_positions(pos, grot)[0] * scale
    return body_mesh(rest.skeleton, pos[0] * scale, ends)


def mannequin_glb(
    rest: Motion,
    *,
    frame: int = 0,
    names: Sequence[str] | None = None,
    ground_root: bool = False,
) -> bytes:
    """A character GLB of ``rest``'s skeleton wearing the mannequin: one skin, the body mesh, one
    material, no animation.

    Parameters
    ----------
    rest:
        The skeleton (joint names find the body's parts) and, at ``frame``, the pose the bind
        pose is taken from as :func:`motion.export.glb.glb_bytes` takes it (the zero pose when
        its legs point down, else that frame; standing on the floor over the origin).
    frame:
        The frame of ``rest`` to use.
    names:
        The joint names to write (default: the skeleton's): a character under names of its own,
        with the body found under the skeleton's.
    ground_root:
        Add Segue's ``ground`` joint above the hips (a root for root motion).

    Returns
    -------
    The GLB file content (metres, Y up), readable by
    :func:`motion.retarget.character.gltf_character`.
    """
    pose = rest.slice(frame, frame + 1)
    return glb_bytes(pose, mesh="body", animation=False, ground_root=ground_root, names=names)
