"""A real Blender for the tests: Blender as a Python module (``bpy`` from PyPI) in a venv of its own.

``tests/run.sh`` makes that venv when ``CI=true`` (``pip install bpy==$SEGUE_BPY_VERSION`` into
``$SEGUE_BPY_VENV``, default ``~/.cache/segue/bpy-venv``, outside the work tree, reused while it
imports) and exports ``SEGUE_BPY_PYTHON``, its interpreter. Elsewhere the tests that need Blender
skip with a message saying how to run them: set ``SEGUE_BPY_PYTHON`` to the Python of any venv
where ``pip install bpy`` (Blender 4.2 LTS or newer; bpy needs Python 3.11) succeeded.

Scripts run in a child process (``python SCRIPT -- ARGS``), never in the test process: bpy is a
whole Blender (hundreds of MB, one scene per process) and lives in another interpreter.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

HANG_GUARD_S = 300.0  # a hang guard, not a pace: importing bpy and a scene takes seconds


def bpy_python() -> Path:
    """The interpreter of the bpy venv (``$SEGUE_BPY_PYTHON``); skips the test when there is none."""
    path = os.environ.get("SEGUE_BPY_PYTHON")
    if not path:
        pytest.skip(
            "no Blender: set SEGUE_BPY_PYTHON to a venv's python with `pip install bpy` "
            "(tests/run.sh makes one with CI=true)"
        )
    python = Path(path)
    if not python.is_file():
        raise AssertionError(f"SEGUE_BPY_PYTHON={path} is not a file")
    return python


def run_blender(
    script: Path, *args: str, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``script`` with Blender's Python: ``sys.argv`` after ``--`` holds ``args``.

    The child gets this process's environment (plus ``env``) without ``PYTHONPATH``/``PYTHONHOME``,
    so that the test venv's packages never shadow Blender's own (its numpy, its glTF add-on).
    """
    base = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    return subprocess.run(
        [str(bpy_python()), str(script), "--", *args],
        capture_output=True, text=True, timeout=HANG_GUARD_S, check=False, env={**base, **(env or {})},
    )  # fmt: skip
