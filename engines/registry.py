"""Which engines and database kinds this installation has.

Engine issues add themselves here. Kinds named in the schemas whose engine has not landed yet are
refused with a clear message instead of being half-built.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from .base import Engine
from .clip import ClipEngine

ENGINES: dict[str, type[Engine]] = {ClipEngine.name: ClipEngine}
KIND_ENGINES: dict[str, type[Engine]] = {cls.kind: cls for cls in ENGINES.values()}

_BUILT_IN: dict[str, tuple[str, str, str]] = {
    "graph": ("engines.graph.engine", "GraphEngine", "graph"),
    "control": ("engines.control.engine", "ControlEngine", "control"),
    "annotations": ("engines.annotations.engine", "AnnotationEngine", "annotated"),
    "rhythm": ("engines.rhythm.engine", "RhythmEngine", "rhythm"),
}
"""Engines imported on first use, by engine name: (module, class, database kind). Keeps the CLI
quick to start; an engine whose module has not landed is reported as unavailable."""


def _load_built_in(name: str) -> None:
    target = _BUILT_IN.get(name)
    if target is None or name in ENGINES:
        return
    try:
        module = importlib.import_module(target[0])
    except ModuleNotFoundError as exc:
        if exc.name is not None and target[0].startswith(exc.name):
            return  # not in this installation: engine_class / kind_class say so
        raise
    register(getattr(module, target[1]))


def _engine_of_kind(kind: str) -> str:
    return next((name for name, t in _BUILT_IN.items() if t[2] == kind), kind)


def register(engine: type[Engine]) -> type[Engine]:
    """Add an engine (usable as a class decorator)."""
    ENGINES[engine.name] = engine
    KIND_ENGINES.setdefault(engine.kind, engine)
    return engine


def load_plugins(spec: str | None) -> list[str]:
    """Import the plugin modules named in ``spec``, comma-separated (``SEGUE_ENGINE_PLUGINS``: modules
    that call :func:`register`, e.g. the test suite's scripted engine); returns their names. Every
    process that runs jobs gets the same list from its settings."""
    names = [n.strip() for n in (spec or "").split(",")]
    loaded = []
    for name in filter(None, names):
        importlib.import_module(name)
        loaded.append(name)
    return loaded


class UnavailableError(LookupError):
    """A kind or engine that exists in the contract but not (yet) in this installation."""


def engine_kind(name: str) -> str:
    """The database kind engine ``name`` needs, without importing a built-in engine (the API checks
    a request against its database with it). Raises :class:`UnavailableError`."""
    if name in ENGINES:
        return ENGINES[name].kind
    if name in _BUILT_IN:
        return _BUILT_IN[name][2]
    return engine_class(name).kind  # raises UnavailableError naming the engines there are


def require_kind(kind: str) -> None:
    """Raise :class:`UnavailableError` unless this installation can build databases of ``kind``
    (built-in kinds are not imported to say so)."""
    if kind not in KIND_ENGINES and not any(t[2] == kind for t in _BUILT_IN.values()):
        kind_class(kind)


def engine_class(name: str) -> type[Engine]:
    """The engine class of a request's ``engine`` (imported on first use)."""
    _load_built_in(name)
    try:
        return ENGINES[name]
    except KeyError:
        raise UnavailableError(
            f"engine {name!r} is not available in this installation "
            f"(available: {', '.join(sorted(ENGINES))})"
        ) from None


def kind_class(kind: str) -> type[Engine]:
    """The engine class that builds and loads databases of ``kind`` (imported on first use)."""
    _load_built_in(_engine_of_kind(kind))
    try:
        return KIND_ENGINES[kind]
    except KeyError:
        raise UnavailableError(
            f"database kind {kind!r} is not available yet: its engine has not landed "
            f"(available kinds: {', '.join(sorted(KIND_ENGINES))})"
        ) from None


def warm_compiled(say: Callable[[str], None] | None = None, force: bool = False) -> float:
    """Compile (or load from numba's cache) the kernels of the engines that have them (the control
    engine's, :mod:`engines.control.warm`) so that no request pays the compile; returns seconds.
    ``say`` gets a line before and after; once done for this installation and cache it returns at
    once unless ``force``."""
    try:
        from .control.warm import warm
    except ModuleNotFoundError:  # an installation without the control engine
        return 0.0
    return warm(say, force)
