"""Fixtures of the browser tests: the real service under uvicorn on 127.0.0.1 (embedded backend) and
Debian's headless Chromium driven by Python playwright (no browser downloads).

Without /usr/bin/chromium (or the playwright package) the tests skip with the reason, except in CI
(``CI=true``), where a missing browser fails them: CI must run them.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from service.client import SegueClient
from tests.live_server import live_server

ARTIFACTS = Path(__file__).resolve().parent / "artifacts"
CHROMIUM = os.environ.get("SEGUE_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def _missing(reason: str) -> None:
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{reason}; CI must run the browser tests (tests/run.sh installs chromium)")
    pytest.skip(reason)


@pytest.fixture(scope="package")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """Base URL of ``uvicorn --factory service.app:create_app`` (2 embedded workers, fresh data dir)."""
    with live_server(tmp_path_factory.mktemp("web-data")) as url:
        yield url


@pytest.fixture(scope="package")
def segue(server: str) -> Iterator[SegueClient]:
    """An API client on the same server (to prepare databases the tools need)."""
    with SegueClient(server) as client:
        yield client


@pytest.fixture(scope="package")
def browser() -> Iterator[Any]:
    """Headless Debian Chromium (skips, or fails in CI, when it or playwright is missing)."""
    if not Path(CHROMIUM).exists() or shutil.which(CHROMIUM) is None:
        _missing(f"{CHROMIUM} is not installed (apt-get install chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _missing("the playwright package is not installed (pip install -e '.[web]')")
    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS, headless=True)
        try:
            yield chromium
        finally:
            chromium.close()


class PageErrors(list[str]):
    """Uncaught page errors and console errors seen during a test."""


@pytest.fixture
def page(browser: Any, server: str) -> Iterator[Any]:
    """A fresh page on the service's front end, ready (``window.__segue.ready``); fails the test on
    uncaught JavaScript errors."""
    context = browser.new_context(viewport={"width": 1400, "height": 820}, accept_downloads=True)
    # every wait without its own timeout (clicks, fills, selectors, navigation) is a hang guard too,
    # not Playwright's 30-s default: a loaded machine is slow, not broken
    context.set_default_timeout(120_000)
    pg = context.new_page()
    errors = PageErrors()
    pg.on("pageerror", lambda exc: errors.append(f"pageerror: {exc}"))
    pg.on("console", lambda msg: errors.append(f"console: {msg.text}") if msg.type == "error" else None)
    pg.goto(server + "/")
    pg.wait_for_function("window.__segue && window.__segue.ready", timeout=120_000)  # a hang guard
    pg.errors = errors
    try:
        yield pg
    finally:
        context.close()
    assert not [e for e in errors if "pageerror" in e], errors


def screenshot(page: Any, name: str) -> Path:
    """Save a screenshot of the whole page to tests/web/artifacts/<name>.png (git-ignored)."""
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path))
    return path
