"""The add-on's zip: ``segue_blender/`` with its modules and ``blender_manifest.toml``, which
Blender 4.2+ installs as an extension (the manifest) or as a legacy add-on (``bl_info``).
Standard library only: ``segue blender-addon`` runs it before anything heavy is imported."""

from __future__ import annotations

import zipfile
from pathlib import Path

ADDON_DIR = Path(__file__).resolve().parent / "segue_blender"
PACKAGE = "segue_blender"
FIXED_TIME = (2026, 1, 1, 0, 0, 0)
"""Every entry's time: the same sources give the same zip, byte for byte."""


def addon_files() -> list[Path]:
    """The add-on's files: its Python modules and manifest (no caches), sorted."""
    files = [p for p in ADDON_DIR.iterdir() if p.is_file() and p.suffix in (".py", ".toml")]
    if not (ADDON_DIR / "__init__.py").is_file() or not (ADDON_DIR / "blender_manifest.toml").is_file():
        raise FileNotFoundError(f"the add-on's sources are not in {ADDON_DIR}")
    return sorted(files)


def write_addon_zip(out: str | Path) -> list[str]:
    """Write the installable zip to ``out``; the names it holds."""
    names = []
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for path in addon_files():
            name = f"{PACKAGE}/{path.name}"
            info = zipfile.ZipInfo(name, FIXED_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, path.read_bytes())
            names.append(name)
    return names
