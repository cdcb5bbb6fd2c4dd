"""Segue's motion core: BVH I/O, skeletons, kinematics and motion operations (pure numpy)."""

from .bvh import BvhLimits, detect_units, parse_bvh, read_bvh, write_bvh
from .errors import BvhError, ExportError, GltfError, MotionError
from .motion import Motion
from .skeleton import Skeleton

__all__ = [
    "BvhError",
    "BvhLimits",
    "ExportError",
    "GltfError",
    "Motion",
    "MotionError",
    "Skeleton",
    "detect_units",
    "parse_bvh",
    "read_bvh",
    "write_bvh",
]
