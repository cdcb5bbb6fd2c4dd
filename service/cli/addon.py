"""``segue blender-addon --out FILE.zip``: the Blender add-on as an installable zip.

Only the standard library (the packer is ``integrations.blender.package``, which imports none of
Segue): the command answers at once."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def cmd_blender_addon(args: argparse.Namespace) -> int:
    from integrations.blender.package import write_addon_zip

    out = Path(args.out)
    if out.suffix.lower() != ".zip":
        print(f"segue: error: {out}: the add-on is a .zip file", file=sys.stderr)
        return 2
    if out.parent != Path() and not out.parent.is_dir():
        print(f"segue: error: {out.parent}: no such folder", file=sys.stderr)
        return 2
    names = write_addon_zip(out)
    print(
        f"{out}: Segue add-on for Blender 4.2+ ({len(names)} files); install it with Edit > Preferences > "
        "Get Extensions > Install from Disk (or Add-ons > Install from Disk)"
    )
    return 0
