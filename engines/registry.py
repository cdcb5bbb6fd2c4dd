"""Which engines and database kinds this installation has: the one table of them.

Each engine is one line of :data:`_BUILT_IN` (its module, class, database kind and the request
and spec models of :mod:`schemas`); the request and spec unions of the OpenAPI document
(:func:`request_union`, :func:`spec_union`) and the validation of requests and specs
(:func:`parse_job_request`, :func:`parse_database_spec`) are built from it, and engine modules are
imported only on first use (keeps the CLI quick to start). Plugins add engines with
:func:`register`. Adding an engine touches its own package, its schema module and one line here.

Validation lives here rather than in :mod:`schemas` because the table of engines is here:
:mod:`schemas` (the layer below the engines) holds the models and cannot import this table, and a
second table there would have to be kept equal to this one.
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Annotated, Any, Union

from pydantic import Field, TypeAdapter

from schemas.annotations import AnnotatedDatabaseSpec, AnnotationRequest
from schemas.bases import DatabaseSpecBase, JobRequestBase
from schemas.control import ControlDatabaseSpec, ControlRequest
from schemas.databases import ClipsDatabaseSpec, GraphDatabaseSpec
from schemas.graph import GraphRequest
from schemas.jobs import ClipRequest, RequestError
from schemas.rhythm import RhythmDatabaseSpec, RhythmRequest

from .base import AnyEngine, EngineError

EngineClass = type[AnyEngine]
"""An engine class, whatever its request and spec models."""


@dataclass(frozen=True, slots=True)
class BuiltIn:
    """A built-in engine before it is imported: its module and class, the database kind it needs
    and its request and spec models."""

    module: str
    cls: str
    kind: str
    request_model: type[JobRequestBase]
    spec_model: type[DatabaseSpecBase]


_BUILT_IN: dict[str, BuiltIn] = {
    "clip": BuiltIn("engines.clip", "ClipEngine", "clips", ClipRequest, ClipsDatabaseSpec),
    "graph": BuiltIn("engines.graph.engine", "GraphEngine", "graph", GraphRequest, GraphDatabaseSpec),
    "control": BuiltIn(
        "engines.control.engine", "ControlEngine", "control", ControlRequest, ControlDatabaseSpec
    ),
    "annotations": BuiltIn(
        "engines.annotations.engine",
        "AnnotationEngine",
        "annotated",
        AnnotationRequest,
        AnnotatedDatabaseSpec,
    ),
    "rhythm": BuiltIn("engines.rhythm.engine", "RhythmEngine", "rhythm", RhythmRequest, RhythmDatabaseSpec),
}
"""The built-in engines by name, imported on first use; an engine whose module has not landed is
reported as unavailable."""

_SPEC_ORDER = ("clips", "control", "graph", "annotated", "rhythm")
"""The order of the spec union's members (as the OpenAPI document has always listed them)."""

ENGINES: dict[str, EngineClass] = {}
KIND_ENGINES: dict[str, EngineClass] = {}


def _request_models() -> dict[str, type[JobRequestBase]]:
    """Request model by engine name: the built-in engines', then the plugins'."""
    models = {name: b.request_model for name, b in _BUILT_IN.items()}
    for name, engine in ENGINES.items():
        models.setdefault(name, engine.request_model)
    return models


def _spec_models() -> tuple[type[DatabaseSpecBase], ...]:
    """The spec model of every database kind, built-in kinds in :data:`_SPEC_ORDER`, then the
    plugins' kinds."""
    by_kind: dict[str, type[DatabaseSpecBase]] = {b.kind: b.spec_model for b in _BUILT_IN.values()}
    for engine in KIND_ENGINES.values():
        by_kind.setdefault(engine.kind, engine.spec_model)
    kinds = [k for k in _SPEC_ORDER if k in by_kind] + [k for k in by_kind if k not in _SPEC_ORDER]
    return tuple(by_kind[k] for k in kinds)


def request_union() -> Any:
    """The discriminated union (on ``engine``) of the built-in engines' request models, for the
    OpenAPI document."""
    models = tuple(b.request_model for b in _BUILT_IN.values())
    return Annotated[Union[models], Field(discriminator="engine")]  # noqa: UP007 (a runtime tuple)


def spec_union() -> Any:
    """The discriminated union (on ``kind``) of the built-in database spec models, for the OpenAPI
    document."""
    by_kind = {b.kind: b.spec_model for b in _BUILT_IN.values()}
    kinds = [k for k in _SPEC_ORDER if k in by_kind] + [k for k in by_kind if k not in _SPEC_ORDER]
    models = tuple(by_kind[k] for k in kinds)
    return Annotated[Union[models], Field(discriminator="kind")]  # noqa: UP007 (a runtime tuple)


def parse_job_request(data: Any) -> JobRequestBase:
    """Validate a job request (dict or JSON text) with its engine's model (plugins' included).

    Raises :class:`schemas.jobs.RequestError` for a non-object or an unknown engine and pydantic's
    ``ValidationError`` for invalid fields.
    """
    if isinstance(data, str | bytes):
        try:
            data = json.loads(data)
        except ValueError as exc:
            raise RequestError(f"the request is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise RequestError("a job request must be a JSON object")
    engine = data.get("engine")
    models = _request_models()
    model = models.get(engine) if isinstance(engine, str) else None
    if model is None:
        raise RequestError(f"unknown engine {engine!r}; available: {', '.join(sorted(models))}")
    return model.model_validate(data)


@lru_cache(maxsize=8)
def _spec_adapter(models: tuple[type[DatabaseSpecBase], ...]) -> TypeAdapter[Any]:
    union: Any = Annotated[Union[models], Field(discriminator="kind")]  # noqa: UP007 (a runtime tuple)
    return TypeAdapter(union)


def parse_database_spec(data: Any) -> DatabaseSpecBase:
    """Validate a database spec (dict or JSON text) against the union of the kinds' spec models
    (plugins' included); raises pydantic's ``ValidationError``."""
    adapter = _spec_adapter(_spec_models())
    if isinstance(data, str | bytes):
        return adapter.validate_json(data)  # type: ignore[no-any-return]
    return adapter.validate_python(data)  # type: ignore[no-any-return]


def _load_built_in(name: str) -> None:
    target = _BUILT_IN.get(name)
    if target is None or name in ENGINES:
        return
    try:
        module = importlib.import_module(target.module)
    except ModuleNotFoundError as exc:
        if exc.name is not None and target.module.startswith(exc.name):
            return  # not in this installation: engine_class / kind_class say so
        raise
    register(getattr(module, target.cls))


def _engine_of_kind(kind: str) -> str:
    return next((name for name, t in _BUILT_IN.items() if t.kind == kind), kind)


def register(engine: EngineClass) -> EngineClass:
    """Add an engine (usable as a class decorator); a plugin's request and spec models become ones
    that :func:`parse_job_request` and :func:`parse_database_spec` validate."""
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
        return _BUILT_IN[name].kind
    return engine_class(name).kind  # raises UnavailableError naming the engines there are


def require_kind(kind: str) -> None:
    """Raise :class:`UnavailableError` unless this installation can build databases of ``kind``
    (built-in kinds are not imported to say so)."""
    if kind not in KIND_ENGINES and not any(t.kind == kind for t in _BUILT_IN.values()):
        kind_class(kind)


def engine_class(name: str) -> EngineClass:
    """The engine class of a request's ``engine`` (imported on first use)."""
    _load_built_in(name)
    try:
        return ENGINES[name]
    except KeyError:
        raise UnavailableError(
            f"engine {name!r} is not available in this installation "
            f"(available: {', '.join(sorted(ENGINES))})"
        ) from None


def kind_class(kind: str) -> EngineClass:
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


_load_built_in("clip")  # the smallest engine, always there (and named when another is missing)


def recording_media_type(head: bytes) -> str | None:
    """The media type of a music recording from its first bytes (WAV, FLAC, Ogg, MP3), else
    ``None`` (the rhythm engine's decoder says what it reads; nothing is decoded here)."""
    from .rhythm.audio import audio_media_type

    return audio_media_type(head)


def recording_beats(data: bytes, tempo_bpm: float | None = None) -> dict[str, Any]:
    """The beats of a music recording, analysed by the engine that dances to music
    (:meth:`engines.base.Engine.recording_beats`); raises :class:`EngineError`."""
    return kind_class("rhythm").recording_beats(data, tempo_bpm)


__all__ = [
    "ENGINES",
    "KIND_ENGINES",
    "BuiltIn",
    "EngineClass",
    "EngineError",
    "UnavailableError",
    "engine_class",
    "engine_kind",
    "kind_class",
    "load_plugins",
    "parse_database_spec",
    "parse_job_request",
    "recording_beats",
    "recording_media_type",
    "register",
    "request_union",
    "require_kind",
    "spec_union",
    "warm_compiled",
]
