"""Every command and JSON block of README.md and docs/ runs as written (see :mod:`tests.docs.examples`
for how each kind of block runs and how a block says it needs a server or cannot run)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from schemas import JobEvent
from service.cli import build_parser, main
from tests.live_server import live_server

from .examples import DOCS, REPO, Block, all_blocks, blocks, problems

SERVER_URL = "http://127.0.0.1:8000"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A live ``segue serve`` (uvicorn, embedded workers) for the blocks marked ``server``."""
    with live_server(tmp_path_factory.mktemp("docs-server")) as url:
        yield url


def _env(**extra: str) -> dict[str, str]:
    bin_dir = str(Path(sys.executable).parent)
    return {
        "PATH": os.pathsep.join([bin_dir, "/usr/local/bin", "/usr/bin", "/bin"]),
        "HOME": os.environ.get("HOME", "/tmp"),
        "PYTHONPATH": str(REPO),
        "LANG": "C.UTF-8",
        **extra,
    }


class Runner:
    """Runs one file's blocks in order in one folder, keeping the last spec, database and request."""

    def __init__(self, folder: Path, server: str | None = None) -> None:
        self.folder, self.server = folder, server
        self.count = 0
        self.spec: dict[str, Any] | None = None
        self.db: Path | None = None
        self.request: dict[str, Any] | None = None
        self.reports: list[tuple[str, dict[str, Any], bool]] = []
        """(where, report, whether the docs promise it is ok) of every request run"""

    def cli(self, block: Block, *argv: str) -> None:
        err = io.StringIO()
        cwd = Path.cwd()
        try:
            os.chdir(self.folder)
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                code = main(list(argv))
        finally:
            os.chdir(cwd)
        assert code == 0, f"{block.where}: segue {' '.join(argv)} failed: {err.getvalue()[-2000:]}"

    def run(self, block: Block) -> None:
        getattr(self, f"_{'sh' if block.lang == 'bash' else block.lang}")(block)

    def _json(self, block: Block) -> None:
        for value in block.json_values():
            self.count += 1
            n = self.count
            assert isinstance(value, dict), f"{block.where}: JSON value {n} is not an object"
            if "kind" in value:
                (self.folder / f"spec-{n}.json").write_text(json.dumps(value))
                self.cli(block, "build", f"spec-{n}.json", "--out", f"db-{n}", "-q")
                self.spec, self.db = value, self.folder / f"db-{n}"
                if self.server:
                    self._post_spec(block, value)
            elif "engine" in value:
                assert self.db is not None, f"{block.where}: a request before any database spec"
                (self.folder / f"request-{n}.json").write_text(json.dumps(value))
                self.cli(
                    block, "synth", f"request-{n}.json", "--db", str(self.db), "--out", f"out-{n}.bvh",
                    "--report", f"report-{n}.json", "-q",
                )  # fmt: skip
                report = json.loads((self.folder / f"report-{n}.json").read_text())
                self.reports.append((f"{block.where} #{n}", report, block.kind != "not-ok"))
                self.request = value
            else:
                pytest.fail(f"{block.where}: JSON value {n} is no spec ('kind') and no request ('engine')")

    def _post_spec(self, block: Block, spec: dict[str, Any]) -> None:
        """The same spec over HTTP: the same content address as ``segue build`` gave."""
        from service.client import SegueClient

        with SegueClient(self.server) as segue:
            info = segue.build_database(spec, timeout=120)
        built = json.loads((self.db / "info.json").read_text()) if self.db else {}
        assert info.id == built.get("id"), f"{block.where}: the API's database is not the CLI's"

    def _sh(self, block: Block) -> None:
        for name, role in block.files.items():
            value = self.spec if role == "spec" else self.request
            assert value is not None, f"{block.where}: no {role} JSON before this block"
            (self.folder / name).write_text(json.dumps(value))
        text = block.text.replace(SERVER_URL, self.server) if self.server else block.text
        r = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", text],
            cwd=self.folder,
            env=_env(**({"SEGUE_URL": self.server} if self.server else {})),
            capture_output=True,
            text=True,
            timeout=300,
        )
        output = f"{r.stdout[-1500:]}\n{r.stderr[-2500:]}"
        assert r.returncode == 0, f"{block.where}: exit {r.returncode}\n{output}"

    def _python(self, block: Block) -> None:
        r = subprocess.run(
            [sys.executable, "-c", block.text],
            cwd=self.folder,
            env=_env(**({"SEGUE_URL": self.server} if self.server else {})),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert r.returncode == 0, f"{block.where}: exit {r.returncode}\n{r.stderr[-2500:]}"


def test_every_block_runs_or_says_why_not() -> None:
    found = all_blocks()
    assert len(found) > 20
    bad = [p for b in found for p in problems(b)]
    assert not bad, "\n".join(bad)


@pytest.mark.slow  # about 45 s: tests/run.sh runs it with CI=true or SEGUE_SLOW=1
@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(REPO)))
def test_examples_run_verbatim(path: Path, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    """The file's blocks in order, in one folder (a live server started for files with ``server``
    blocks); every request's report must say ``ok`` (the examples are ones the samples satisfy),
    except in blocks marked ``not-ok``, whose reports must say what is not."""
    todo = [b for b in blocks(path) if b.kind in ("run", "server", "not-ok")]
    if not todo:
        pytest.skip("no runnable block")
    url = request.getfixturevalue("server") if any(b.kind == "server" for b in todo) else None
    runner = Runner(tmp_path, url)
    for block in todo:
        runner.run(block)
    wrong = [(where, r.get("ok"), r.get("reasons")) for where, r, ok in runner.reports if r["ok"] is not ok]
    assert not wrong, f"examples whose report is not what the docs say: {wrong}"
    assert all(r["reasons"] for _, r, ok in runner.reports if not ok)


@pytest.mark.parametrize("block", [b for b in all_blocks() if b.kind == "event"], ids=lambda b: b.where)
def test_event_examples_are_events(block: Block) -> None:
    for value in block.json_values():
        JobEvent.model_validate(value)


@pytest.mark.parametrize("block", [b for b in all_blocks() if b.kind == "synopsis"], ids=lambda b: b.where)
def test_synopses_name_real_commands_and_options(block: Block) -> None:
    """Each ``segue COMMAND [--option ...]`` of a command summary exists in the CLI."""
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    for line in block.text.splitlines():
        for cmd, rest in re.findall(r"\bsegue (\w[\w-]*)([^#;]*)", line):
            assert cmd in commands, f"{block.where}: no command 'segue {cmd}'"
            options = {o for a in commands[cmd]._actions for o in a.option_strings}
            for opt in re.findall(r"(--[\w-]+)", rest):
                assert opt in options, f"{block.where}: 'segue {cmd}' has no option {opt}"
