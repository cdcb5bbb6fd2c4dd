"""The browser front end: the static files of ``web/`` served at ``/`` (for every path no API route
matches), and the bundled sample clips at ``/samples/{name}`` so the page can offer them for upload.

The page itself talks to the service only through the public API (``/v1/...``); these routes serve
files and nothing else. ``GET /`` returns ``web/index.html``.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse
from pydantic import BaseModel, Field, JsonValue
from starlette.staticfiles import StaticFiles
from starlette.types import Receive, Scope, Send

import web
from motion.samples import SAMPLES, is_clip_sample, sample_path

from .demos import DEMOS
from .errors import ApiError

WEB_DIR = Path(web.__file__).resolve().parent
"""The ``web/`` package directory (index.html, js/, vendor/): installed as package data."""


class _StaticRoute:
    """What the HTTP metrics label static files with (one route template for all of them)."""

    path = "/{static file}"


class WebFiles(StaticFiles):
    """Static files mounted at ``/``: HTTP only (a WebSocket to an unknown path is closed, not an
    assertion error), ``index.html`` for directories."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await send({"type": "websocket.close", "code": 1000})
            return
        scope["route"] = _StaticRoute
        await super().__call__(scope, receive, send)


class DemoOffer(BaseModel):
    """One ``segue demo ENGINE`` database as the page offers it on a first visit."""

    name: str
    title: str
    tool: str = Field(description="the browser tool that uses it (Path, Partner, ...)")
    spec: dict[str, JsonValue] = Field(description="the database spec (bundled samples as sample:NAME)")
    request: dict[str, JsonValue] = Field(description="the demo's job request")


def sample_files() -> dict[str, str]:
    """The bundled sample clips: file name (``*.bvh.gz``) -> sample name (:data:`motion.samples.SAMPLES`;
    the MIDI song is not a clip, and requests name it ``sample:song``)."""
    return {file: name for name, file in SAMPLES.items() if is_clip_sample(name)}


def mount_web(app: FastAPI) -> None:
    """Add ``/samples`` (list and files), ``/demos`` and serve ``web/`` at ``/`` for every path no route
    matches (``/`` is ``index.html``)."""

    @app.get("/samples", include_in_schema=False)
    async def list_samples() -> dict[str, str]:
        """The bundled samples the page offers: file name -> sample name (not part of the API)."""
        return sample_files()

    @app.get("/demos", include_in_schema=False)
    async def list_demos() -> list[DemoOffer]:
        """The databases ``segue demo ENGINE`` builds (on bundled samples), for the page's one-click
        "try it" on a first visit: name, title, the browser tool, the spec and the demo's request."""
        return [
            DemoOffer(name=d.name, title=d.title, tool=d.tool, spec=d.spec, request=d.request)
            for d in DEMOS.values()
        ]

    @app.get("/samples/{name}", include_in_schema=False)
    async def get_sample(name: str) -> FileResponse:
        """One bundled sample's bytes (gzip BVH), for the page to upload with ``POST /v1/clips``."""
        sample = sample_files().get(name)
        if sample is None:
            raise ApiError(404, "not_found", f"no bundled sample {name!r}; see GET /samples")
        return FileResponse(sample_path(sample), media_type="application/gzip", filename=name)

    # The router's default handler, not a mount at "/": it runs only when no route matches at all,
    # so the API keeps its own answers (a 405 for a known path with another method, JSON 404s).
    app.router.default = WebFiles(directory=WEB_DIR, html=True)
