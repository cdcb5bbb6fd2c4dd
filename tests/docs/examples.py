"""The fenced code blocks of README.md and docs/*.md, and what the docs test does with each.

A block is run as it is written: ``sh``/``bash`` blocks with bash (``segue`` on PATH), ``python``
blocks with this interpreter, ``json`` blocks as database specs (objects with ``"kind"``, built with
``segue build``) and requests (objects with ``"engine"``, run with ``segue synth`` against the last
spec before them in the same file). Each file's blocks run in order in one fresh folder.

An HTML comment on the line before a block says what else to do with it (rendered Markdown hides it):

``<!-- docs-test: server -->``
    needs a running ``segue serve``: run against a live server (``http://127.0.0.1:8000`` in the
    block becomes its address; Python clients read ``SEGUE_URL``);
``<!-- docs-test: files db.json=spec request.json=request -->``
    before a shell block: write the last spec / request JSON of the file to these files;
``<!-- docs-test: not-ok (why) -->``
    run like any JSON block, but its requests must come back *not* ok (an example of what the
    report says about a request the data cannot satisfy);
``<!-- docs-test: event -->``
    JSON that is an example of an event: checked against :class:`schemas.JobEvent`;
``<!-- docs-test: synopsis -->``
    a command summary: every ``segue COMMAND`` and ``--option`` in it must exist in ``segue``'s help;
``<!-- docs-test: skip (reason) -->``
    not runnable, with the reason (an excerpt, a list of endpoints, the test command itself...).

Any other block without a language or with a marker the test does not know fails the test: every
block is run or says why not.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]

_FENCE = re.compile(r"^```(?P<lang>[\w-]*)[ \t]*\n(?P<body>.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
_MARKER = re.compile(r"<!--\s*docs-test:\s*(?P<what>.*?)\s*-->\s*$")
KINDS = ("run", "server", "not-ok", "event", "synopsis", "skip")


@dataclass(frozen=True)
class Block:
    """One fenced block: where it is, its language, its text and its marker."""

    path: Path
    line: int
    lang: str
    text: str
    marker: str = ""
    files: dict[str, str] = field(default_factory=dict)

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(REPO)}:{self.line}"

    @property
    def kind(self) -> str:
        """``run``, ``server``, ``not-ok``, ``event``, ``synopsis`` or ``skip``."""
        word = self.marker.split(maxsplit=1)[0] if self.marker else ""
        if word == "files" or not word:
            return "run"
        return word

    def json_values(self) -> list[Any]:
        """The JSON values of a ``json`` block, in order (a block may hold several)."""
        decoder = json.JSONDecoder()
        text, pos, out = self.text, 0, []
        while True:
            while pos < len(text) and text[pos].isspace():
                pos += 1
            if pos >= len(text):
                return out
            value, pos = decoder.raw_decode(text, pos)
            out.append(value)


def blocks(path: Path) -> list[Block]:
    """Every fenced block of a Markdown file, with the marker on the line before it."""
    text = path.read_text(encoding="utf-8")
    out = []
    for m in _FENCE.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        marker = _MARKER.search(before)
        what = marker.group("what") if marker else ""
        files: dict[str, str] = {}
        if what.startswith("files"):
            for item in what.split()[1:]:
                name, _, role = item.partition("=")
                files[name] = role
        out.append(Block(path, line, m.group("lang").lower(), m.group("body"), what, files))
    return out


def all_blocks() -> list[Block]:
    return [b for path in DOCS for b in blocks(path)]


def problems(block: Block) -> list[str]:
    """Why a block can be neither run nor skipped (an unknown marker, no language...)."""
    out = []
    if block.kind not in KINDS:
        out.append(f"{block.where}: unknown docs-test marker {block.marker!r} (one of {', '.join(KINDS)})")
    if block.kind in ("skip", "not-ok") and not re.search(r"\(.+\)", block.marker):
        out.append(f"{block.where}: say why in brackets: <!-- docs-test: {block.kind} (why) -->")
    if block.kind == "not-ok" and block.lang != "json":
        out.append(f"{block.where}: not-ok marks a JSON block of requests")
    if block.kind in ("run", "server") and block.lang not in ("sh", "bash", "python", "json"):
        out.append(f"{block.where}: a block to run needs a language (sh, bash, python, json): {block.lang!r}")
    if block.files and block.lang not in ("sh", "bash"):
        out.append(f"{block.where}: 'files' goes before a shell block")
    for role in block.files.values():
        if role not in ("spec", "request"):
            out.append(f"{block.where}: files NAME=spec or NAME=request, not {role!r}")
    return out
