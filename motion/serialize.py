"""Motions as plain arrays (for ``.npz`` storage and caches: never pickle).

:func:`motion_to_arrays` and :func:`motion_from_arrays` are exact inverses; every value is a numpy
array of numbers or unicode strings, so ``np.load(..., allow_pickle=False)`` reads them back.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import MotionError
from .motion import Motion
from .skeleton import Skeleton


def skeleton_to_arrays(skeleton: Skeleton, prefix: str = "") -> dict[str, npt.NDArray[Any]]:
    """Arrays describing a skeleton, keys prefixed by ``prefix``."""
    return {
        f"{prefix}names": np.array(skeleton.names, dtype=str),
        f"{prefix}parents": np.asarray(skeleton.parents, dtype=np.int64),
        f"{prefix}offsets": np.asarray(skeleton.offsets),
        f"{prefix}channels": np.array(json.dumps([list(c) for c in skeleton.channels])),
        f"{prefix}end_site_parents": np.asarray(skeleton.end_site_parents, dtype=np.int64),
        f"{prefix}end_site_offsets": np.asarray(skeleton.end_site_offsets),
    }


def skeleton_from_arrays(arrays: Any, prefix: str = "") -> Skeleton:
    """Inverse of :func:`skeleton_to_arrays` (``arrays``: a dict or an ``NpzFile``)."""
    try:
        return Skeleton(
            tuple(str(n) for n in arrays[f"{prefix}names"]),
            np.asarray(arrays[f"{prefix}parents"], dtype=np.intp),
            np.asarray(arrays[f"{prefix}offsets"], dtype=np.float64),
            tuple(tuple(c) for c in json.loads(str(arrays[f"{prefix}channels"]))),
            np.asarray(arrays[f"{prefix}end_site_parents"], dtype=np.intp),
            np.asarray(arrays[f"{prefix}end_site_offsets"], dtype=np.float64),
        )
    except KeyError as exc:
        raise MotionError(f"stored skeleton lacks {exc.args[0]!r}") from None


def motion_to_arrays(motion: Motion, prefix: str = "") -> dict[str, npt.NDArray[Any]]:
    """Arrays describing a motion (skeleton included), keys prefixed by ``prefix``."""
    out = skeleton_to_arrays(motion.skeleton, f"{prefix}skeleton.")
    out.update(
        {
            f"{prefix}root_positions": np.ascontiguousarray(motion.root_positions),
            f"{prefix}rotations": np.ascontiguousarray(motion.rotations),
            f"{prefix}joint_translations": np.ascontiguousarray(motion.joint_translations),
            f"{prefix}fps": np.array(motion.fps, dtype=np.float64),
            f"{prefix}units": np.array(motion.units),
            f"{prefix}name": np.array(motion.name),
        }
    )
    return out


def motion_from_arrays(arrays: Any, prefix: str = "") -> Motion:
    """Inverse of :func:`motion_to_arrays`."""
    try:
        return Motion(
            skeleton_from_arrays(arrays, f"{prefix}skeleton."),
            np.asarray(arrays[f"{prefix}root_positions"], dtype=np.float64),
            np.asarray(arrays[f"{prefix}rotations"], dtype=np.float64),
            float(arrays[f"{prefix}fps"]),
            np.asarray(arrays[f"{prefix}joint_translations"], dtype=np.float64),
            str(arrays[f"{prefix}units"]),
            str(arrays[f"{prefix}name"]),
        )
    except KeyError as exc:
        raise MotionError(f"stored motion lacks {exc.args[0]!r}") from None
