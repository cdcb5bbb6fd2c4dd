"""Typed at the edges: no route handler, and no dependency of one, takes or returns ``Any``."""

from __future__ import annotations

import typing
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute, APIWebSocketRoute

from service.app import create_app
from service.settings import Settings


def mentions_any(annotation: object) -> bool:
    """True when a type hint is ``Any`` or holds it anywhere (``list[Any]``, ``Annotated[Any, ...]``)."""
    if annotation is Any:
        return True
    return any(mentions_any(arg) for arg in typing.get_args(annotation) if not isinstance(arg, str | int))


def calls(dependant: Dependant) -> Iterator[Callable[..., object]]:
    """A route's endpoint and every dependency under it."""
    if dependant.call is not None:
        yield dependant.call
    for sub in dependant.dependencies:
        yield from calls(sub)


def untyped(call: Callable[..., object]) -> list[str]:
    """The parameters (and return) of ``call`` hinted with ``Any`` or not hinted at all."""
    target = call if callable(call) and hasattr(call, "__code__") else type(call).__call__
    hints = typing.get_type_hints(target, include_extras=True)
    names = [n for n in target.__code__.co_varnames[: target.__code__.co_argcount] if n != "self"]
    out = [f"{name}: {hints.get(name, 'no hint')}" for name in names if mentions_any(hints.get(name, Any))]
    if mentions_any(hints.get("return", Any)):
        out.append(f"return: {hints.get('return', 'no hint')}")
    return out


def api_routes(routes: list[Any]) -> Iterator[APIRoute | APIWebSocketRoute]:
    """Every API route, including those of included routers (FastAPI keeps them as wrappers that
    hold the ``original_router``)."""
    for route in routes:
        if isinstance(route, APIRoute | APIWebSocketRoute):
            yield route
        elif hasattr(route, "original_router"):
            yield from api_routes(route.original_router.routes)


def test_no_route_takes_any(tmp_path: Path) -> None:
    app = create_app(Settings(data_dir=tmp_path))
    problems = {}
    routes = list(api_routes(app.routes))
    assert len(routes) > 20
    for route in routes:
        for call in calls(route.dependant):
            found = untyped(call)
            if found and call.__module__.startswith("service."):
                problems[f"{route.path} {getattr(call, '__qualname__', call)}"] = found
    assert problems == {}


def test_the_check_sees_any() -> None:
    def loose(request: Any, n: int) -> list[Any]:
        return [request, n]

    assert untyped(loose) == ["request: typing.Any", "return: list[typing.Any]"]
    assert mentions_any(dict[str, typing.Annotated[Any, "x"]])
