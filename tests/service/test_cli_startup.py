"""``segue --help``, every ``segue COMMAND --help`` and argument errors answer before anything heavy
is imported (no numpy, scipy, scikit-learn, pydantic, fastapi or engine): the time it takes (bar: 0.1 s
above bare Python) is measured by ``bench/cli_startup.py``; this test keeps the imports that decide
it from coming back, without a clock."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from motion.export.targets import TARGETS as MOTION_TARGETS
from motion.io import OUTPUT_SUFFIXES as MOTION_SUFFIXES
from motion.units import METRES_PER_UNIT
from service import cli

REPO = Path(__file__).resolve().parents[2]
HEAVY = ("numpy", "scipy", "sklearn", "pydantic", "fastapi", "engines", "motion", "schemas", "workers")

PROBE = """
import sys
from service.cli import main
for argv in {argvs!r}:
    try:
        main(argv)
    except SystemExit as exc:
        assert exc.code in (0, 2), exc.code
print("HEAVY:" + ",".join(sorted({{m.split(".")[0] for m in sys.modules}} & set({heavy!r}))))
"""


def subcommands() -> list[str]:
    sub = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return list(sub.choices)


def test_help_and_argument_errors_import_nothing_heavy() -> None:
    assert {"inspect", "demo", "synth", "serve", "worker"} <= set(subcommands())
    argvs = [
        ["--help"],
        *([name, "--help"] for name in subcommands()),
        ["convert"],  # missing arguments
        ["inspect", "x.bvh", "--units", "furlong"],  # a bad choice
        ["demo", "dance"],
        ["frobnicate"],
    ]
    r = subprocess.run(
        [sys.executable, "-c", PROBE.format(argvs=argvs, heavy=HEAVY)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    heavy = r.stdout.strip().splitlines()[-1]
    assert heavy == "HEAVY:", f"imported before answering: {heavy}"
    assert "usage: segue" in r.stdout and "invalid choice: 'furlong'" in r.stderr


def test_option_choices_are_the_cores() -> None:
    """The CLI spells the core's choices itself (importing them would import numpy)."""
    assert set(cli.UNITS) == set(METRES_PER_UNIT)
    assert set(cli.TARGETS) == set(MOTION_TARGETS)
    assert tuple(cli.OUTPUT_SUFFIXES) == tuple(MOTION_SUFFIXES)
    from motion.bvh import DEFAULT_MAX_JOINT_FRAMES

    assert cli.DEFAULT_MAX_JOINT_FRAMES == DEFAULT_MAX_JOINT_FRAMES
