"""The command line's manners: help text for every option, ``--version``, quiet ends into a closed
pipe, and ``segue worker`` taking its Redis URL from the environment."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import pytest

from service import cli
from workers.settings import Settings, get_settings

REPO = Path(__file__).resolve().parents[2]


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_option_of_every_subcommand_has_help_text() -> None:
    commands = _subcommands()
    assert {"serve", "worker", "build", "synth", "graph-edit", "samples"} <= set(commands)
    missing = [
        f"segue {name} {action.option_strings or action.dest}"
        for name, parser in commands.items()
        for action in parser._actions
        if not (action.help or "").strip()
    ]
    assert missing == []
    no_description = [name for name, parser in commands.items() if not (parser.description or "").strip()]
    assert no_description == []


def test_serve_help_states_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(["serve", "--help"])
    assert exc.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "default 127.0.0.1" in out and "default 8000" in out and "default info" in out


def test_samples_help_describes_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        cli.main(["samples", "--help"])
    assert "sample:NAME" in capsys.readouterr().out


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"segue {version('segue')}"


def _into_closed_pipe(*argv: str) -> subprocess.CompletedProcess[str]:
    """Run ``segue ARGV`` with stdout a pipe whose reader has gone (as ``| head`` leaves it)."""
    read, write = os.pipe()
    os.close(read)
    try:
        return subprocess.run(
            [sys.executable, "-m", "service.cli", *argv],
            cwd=REPO,
            stdout=write,
            stderr=subprocess.PIPE,
            text=True,
            timeout=300,
            env={**os.environ, "PYTHONPATH": str(REPO)},
        )
    finally:
        os.close(write)


@pytest.mark.parametrize(
    "argv", [("samples",), ("inspect", "sample:walk"), ("beats", "sample:walk", "--json")]
)
def test_output_into_a_closed_pipe_ends_quietly(argv: tuple[str, ...]) -> None:
    r = _into_closed_pipe(*argv)
    assert r.stderr == ""
    assert r.returncode == cli.SIGPIPE_STATUS


def test_worker_takes_the_redis_url_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    import workers.redis_worker as redis_worker

    seen: list[Settings] = []
    monkeypatch.setattr(redis_worker, "serve", lambda settings, **kw: seen.append(settings) or 0)
    monkeypatch.setenv("SEGUE_REDIS_URL", "redis://127.0.0.1:6390/3")
    get_settings.cache_clear()
    try:
        assert cli.main(["worker", "--name", "w1"]) == 0
    finally:
        get_settings.cache_clear()
    assert seen[0].redis_url == "redis://127.0.0.1:6390/3" and seen[0].worker_name == "w1"


def test_worker_without_any_redis_url_says_so(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("SEGUE_REDIS_URL", raising=False)
    get_settings.cache_clear()
    try:
        assert cli.main(["worker"]) == 2
    finally:
        get_settings.cache_clear()
    assert "give --redis URL or set SEGUE_REDIS_URL" in capsys.readouterr().err


def test_worker_data_help_calls_it_this_workers_own_directory() -> None:
    """Across hosts a worker's ``--data`` is its own cache, shared with nobody (issue 39)."""
    worker = _subcommands()["worker"]
    data = next(a for a in worker._actions if "--data" in a.option_strings)
    assert "shared with the API" not in str(data.help)
    assert "cache" in str(data.help) and "SEGUE_STORE_URL" in str(data.help)
