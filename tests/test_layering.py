"""The layering rule of ``../shared/DESIGN.md`` and ``docs/architecture.md``, kept by a test.

Data flows one way: file -> ``motion`` -> database (``engines``) -> job (``workers``) -> events and
results (``service``) -> client. So:

* ``motion`` imports no other package of the project;
* ``schemas`` imports none but ``motion``; ``engines`` imports ``motion`` and ``schemas`` only;
* ``workers`` never imports ``service``;
* ``workers`` and ``service`` reach engines only through ``engines``, ``engines.registry`` and
  ``engines.base`` (an engine's knowledge is asked of its class, never imported from its package).

Every import counts, at the top of a module or inside a function (a lazy import is still a
dependency), relative ones resolved.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("motion", "engines", "schemas", "service", "workers")

FORBIDDEN: dict[str, frozenset[str]] = {
    "motion": frozenset({"engines", "schemas", "service", "workers", "web"}),
    "schemas": frozenset({"engines", "service", "workers", "web"}),
    "engines": frozenset({"service", "workers", "web"}),
    "workers": frozenset({"service", "web"}),
    "service": frozenset(),
}
"""Packages each package must not import."""

ENGINE_FACE = frozenset({"engines", "engines.registry", "engines.base"})
"""The only engine modules the packages above ``engines`` (workers, service) may import."""
ABOVE_ENGINES = frozenset({"workers", "service"})


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_module(dotted: str) -> bool:
    base = ROOT.joinpath(*dotted.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def imports_of(path: Path) -> list[tuple[int, str]]:
    """``(line, module)`` for every import in a source file (``from a import b`` gives ``a.b`` when
    ``b`` is a module of the project, else ``a``)."""
    module = _module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            out.extend((node.lineno, alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            for alias in node.names:
                full = f"{base}.{alias.name}"
                out.append((node.lineno, full if _is_module(full) else base))
    return out


def violations(package: str) -> list[str]:
    """Every import of ``package`` that breaks the rule, as ``file:line: module``."""
    found = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for line, name in imports_of(path):
            top = name.split(".")[0]
            bad = top in FORBIDDEN[package]
            if package in ABOVE_ENGINES and top == "engines":
                bad = name not in ENGINE_FACE
            if bad:
                found.append(f"{path.relative_to(ROOT)}:{line}: {name}")
    return found


@pytest.mark.parametrize("package", PACKAGES)
def test_layering(package: str) -> None:
    assert violations(package) == []


def test_the_checker_sees_violations() -> None:
    """The checker itself: relative and lazy imports resolve to the module they name."""
    probe = ROOT / "service" / "_layering_probe.py"
    probe.write_text(
        "def f():\n    from engines.annotations import search\n    from .routes import jobs\n",
        encoding="utf-8",
    )
    try:
        assert [name for _, name in imports_of(probe)] == [
            "engines.annotations.search",
            "service.routes.jobs",
        ]
        assert violations("service") == ["service/_layering_probe.py:2: engines.annotations.search"]
    finally:
        probe.unlink()
    probe = ROOT / "workers" / "_layering_probe.py"
    probe.write_text(
        "from engines.rhythm.audio import audio_beats\nfrom engines.base import Run\n", encoding="utf-8"
    )
    try:
        assert violations("workers") == ["workers/_layering_probe.py:1: engines.rhythm.audio"]
    finally:
        probe.unlink()


BLENDER_ADDON = ROOT / "integrations" / "blender" / "segue_blender"
BLENDER_OWN = frozenset({"bpy", "mathutils", "gpu", "gpu_extras"})
"""What Blender gives its add-ons besides the standard library."""


def test_the_blender_addon_is_a_thin_client_of_the_http_api() -> None:
    """The add-on runs in Blender's bundled Python: it imports the standard library, Blender's own
    modules and itself, never Segue (motion, engines, schemas, service, workers, web) nor a
    third-party package (numpy, scipy, pydantic...); and its plain modules import no ``bpy`` at
    their top, so they are tested outside Blender."""
    import sys

    allowed = set(sys.stdlib_module_names) | BLENDER_OWN | {"integrations"}
    plain = {"client", "gltf", "mat4", "binding", "axes", "authoring", "roles", "bvh", "jobs",
             "local_service", "state", "__init__"}  # fmt: skip
    bad = []
    for path in sorted(BLENDER_ADDON.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        top_level = {id(n) for n in tree.body}
        for line, name in imports_of(path):
            top = name.split(".")[0]
            if top not in allowed:
                bad.append(f"{path.name}:{line}: {name}")
        if path.stem in plain:
            for node in tree.body:
                if isinstance(node, ast.Import | ast.ImportFrom) and id(node) in top_level:
                    names = (
                        [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                    )
                    if any(n.split(".")[0] in BLENDER_OWN for n in names):
                        bad.append(f"{path.name}:{node.lineno}: {names} at the top of a plain module")
    assert bad == []
