"""Root trajectories of a library's clips (:class:`engines.graph.model.RootTracks`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from motion.contacts import detect_contacts, foot_joints
from motion.errors import MotionError
from motion.ground import ground_frames

from ..library import MotionLibrary
from .model import FootContacts, RootTracks


def root_tracks(
    library: MotionLibrary, positions: Sequence[npt.NDArray[np.float64]] | None = None
) -> RootTracks:
    """Per frame of every clip (concatenated in library order): the body's floor position ``[x, z]``
    (metres; the :func:`motion.ground.body_root` joint, not a static joint 0) and its heading
    (radians about +Y, 0 = facing +Z), unwrapped within each clip (:func:`motion.ground.heading`)."""
    xz, yaw = [], []
    for i, m in enumerate(library.motions):
        p, h = ground_frames(m, None if positions is None else positions[i])
        xz.append(np.asarray(p, dtype=np.float64))
        yaw.append(np.unwrap(np.asarray(h, dtype=np.float64)))
    counts = np.array([m.num_frames for m in library.motions], dtype=np.int64)
    offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    return RootTracks(offsets, np.concatenate(xz), np.concatenate(yaw))


def foot_contacts(
    library: MotionLibrary, positions: Sequence[npt.NDArray[np.float64]] | None = None
) -> FootContacts:
    """Foot contacts of every frame of every clip (concatenated in library order):
    :func:`motion.contacts.detect_contacts` on each clip with the skeleton's foot joints (none
    when it has no foot joints). ``positions``: each clip's global joint positions, if known."""
    n = sum(m.num_frames for m in library.motions)
    try:
        joints = np.asarray(foot_joints(library.motions[0].skeleton), dtype=np.int64)
    except MotionError:
        return FootContacts(np.zeros(0, np.int64), np.zeros((n, 0), dtype=bool))
    flags = [
        detect_contacts(m, joints, positions=None if positions is None else positions[i])[1]
        for i, m in enumerate(library.motions)
    ]
    return FootContacts(joints, np.concatenate(flags).astype(bool))
