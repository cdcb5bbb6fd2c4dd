"""A check shared by the engines' database tests: a database dataclass's ``to_arrays`` gives back
exactly the stored arrays its ``from_arrays`` read (names, order, dtypes, bytes)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


def assert_same_arrays(stored: Mapping[str, Any], written: Mapping[str, Any], prefix: str) -> None:
    """``written`` holds the ``prefix`` arrays of ``stored``, in their order, with equal dtypes,
    shapes and bytes."""
    names = [k for k in stored if k.startswith(prefix)]
    assert names and list(written) == names
    for name in names:
        a, b = np.asarray(stored[name]), np.asarray(written[name])
        assert (a.dtype, a.shape) == (b.dtype, b.shape), name
        assert a.tobytes() == b.tobytes(), name
