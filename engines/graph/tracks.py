"""Root trajectories of a library's clips (:class:`engines.graph.model.RootTracks`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from motion.ground import ground_frames

from ..library import MotionLibrary
from .model import RootTracks


def root_tracks(
    library: MotionLibrary, positions: Sequence[npt.NDArray[np.float64]] | None = None
) -> RootTracks:
    """Per frame of every clip (concatenated in library order): the body's floor position ``[x, z]``
    (metres; the :func:`motion.ground.body_root` joint, not a static joint 0) and its heading
    (radians about +Y, 0 = facing +Z), unwrapped within each clip (:func:`motion.ground.heading`)."""
    xz, yaw = [], []
    for m in library.motions:
        p, h = ground_frames(m)
        xz.append(np.asarray(p, dtype=np.float64))
        yaw.append(np.unwrap(np.asarray(h, dtype=np.float64)))
    counts = np.array([m.num_frames for m in library.motions], dtype=np.int64)
    offsets = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    return RootTracks(offsets, np.concatenate(xz), np.concatenate(yaw))
