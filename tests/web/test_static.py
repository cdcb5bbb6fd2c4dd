"""The front end's files without a browser: vendored three.js matches web/vendor/VERSIONS.md, every
module import resolves, and the service serves the page at / after its API routes."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.settings import Settings
from service.web import WEB_DIR

VENDOR = WEB_DIR / "vendor"


def test_vendored_files_match_their_recorded_hashes() -> None:
    table = dict(
        re.findall(r"^\| `([^`]+)` \| `([0-9a-f]{64})` \|$", (VENDOR / "VERSIONS.md").read_text(), re.M)
    )
    assert "build/three.module.js" in table and "examples/jsm/loaders/BVHLoader.js" in table
    files = {p.relative_to(VENDOR / "three").as_posix() for p in (VENDOR / "three").rglob("*") if p.is_file()}
    assert files == set(table), "every vendored file is listed in VERSIONS.md, and only those"
    for name, digest in table.items():
        assert hashlib.sha256((VENDOR / "three" / name).read_bytes()).hexdigest() == digest, name


def _import_map() -> dict[str, str]:
    html = (WEB_DIR / "index.html").read_text()
    block = re.search(r'<script type="importmap">(.*?)</script>', html, re.S)
    assert block is not None
    return dict(re.findall(r'"([^"]+)":\s*"([^"]+)"', block.group(1)))


def _resolve(spec: str, importer: Path, imports: dict[str, str]) -> Path:
    if spec.startswith("."):
        return (importer.parent / spec).resolve()
    if spec in imports:
        return (WEB_DIR / imports[spec]).resolve()
    prefix = max((p for p in imports if p.endswith("/") and spec.startswith(p)), key=len, default=None)
    assert prefix is not None, f"{importer.name}: bare import {spec!r} is not in the import map"
    return (WEB_DIR / imports[prefix] / spec[len(prefix) :]).resolve()


def test_every_module_import_resolves() -> None:
    """Follow the imports from js/app.js through the import map: every file exists (no build step)."""
    imports = _import_map()
    todo, seen = [WEB_DIR / "js" / "app.js"], set()
    pattern = re.compile(
        r"""^\s*(?:import|export)\s[^'"]*?from\s+['"]([^'"]+)['"]|^\s*import\s+['"]([^'"]+)['"]""", re.M
    )
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        assert path.is_file(), f"missing module {path}"
        for match in pattern.finditer(path.read_text(encoding="utf-8")):
            todo.append(_resolve(match.group(1) or match.group(2), path, imports))
    names = {p.name for p in seen}
    assert {"three.module.js", "three.core.js", "OrbitControls.js", "BVHLoader.js", "GLTFLoader.js"} <= names


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> TestClient:
    """The app without its lifespan (no backend): enough for static files and routing."""
    return TestClient(
        create_app(Settings(data_dir=tmp_path_factory.mktemp("static-data"))), base_url="http://localhost"
    )


def test_root_serves_the_page_and_api_routes_come_first(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert '<script type="importmap">' in page.text
    js = client.get("/vendor/three/build/three.module.js")
    assert js.status_code == 200 and "javascript" in js.headers["content-type"]
    assert client.get("/openapi.json").json()["info"]["title"] == "Segue"
    missing = client.get("/v1/no-such-route")
    assert missing.status_code == 404 and missing.json()["error"]["code"] == "http_404"
    wrong_method = client.put("/v1/clips")  # a known API path keeps its 405 (with Allow)
    assert wrong_method.status_code == 405 and "POST" in wrong_method.headers["allow"]
    assert client.get("/no-such-file.js").status_code == 404


def test_samples_are_listed_and_served(client: TestClient) -> None:
    samples = client.get("/samples").json()
    assert samples["07_01_walk_daz.bvh.gz"] == "walk" and len(samples) == 20  # the clips, not the song
    assert all(f.endswith(".bvh.gz") for f in samples)
    data = client.get("/samples/07_01_walk_daz.bvh.gz")
    assert data.status_code == 200 and data.content[:2] == b"\x1f\x8b"
    bad = client.get("/samples/__init__.py")
    assert bad.status_code == 404 and bad.json()["error"]["code"] == "not_found"


def test_websocket_to_a_static_path_is_closed(client: TestClient) -> None:
    from starlette.websockets import WebSocketDisconnect

    with pytest.raises(WebSocketDisconnect), client.websocket_connect("/nothing-here") as ws:
        ws.receive_text()


def test_web_files_are_package_data() -> None:
    """pyproject ships web/ (html, css, js, vendored three.js) with the package."""
    text = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text()
    line = next(line for line in text.splitlines() if line.startswith('"web" = '))
    for pattern in ("*.html", "*.css", "js/*.js", "vendor/three/**/*"):
        assert f'"{pattern}"' in line


def test_the_pages_unit_table_is_the_services() -> None:
    """web/js/bvh.js draws clips in the unit the service reports (ClipInfo.units): it knows every
    unit of motion.units (cmu-scaled too: the bundled salsa samples declare it) and guesses among
    the same ones."""
    from motion.units import GUESSED_UNITS, METRES_PER_UNIT

    js = (WEB_DIR / "js" / "bvh.js").read_text()
    table = re.search(r"METRES_PER_UNIT = \{(.*?)\};", js)
    guessed = re.search(r"GUESSED_UNITS = \[(.*?)\];", js)
    assert table is not None and guessed is not None
    entries = dict(re.findall(r"'?([\w-]+)'?: ([\d./ ]+)", table.group(1)))
    assert set(entries) == set(METRES_PER_UNIT)
    for unit, expr in entries.items():
        a, _, b = expr.partition("/")
        value = float(a) / float(b) if b else float(a)
        assert value == pytest.approx(METRES_PER_UNIT[unit]), unit
    assert re.findall(r"'([\w-]+)'", guessed.group(1)) == list(GUESSED_UNITS)
