"""``segue serve``, ``worker`` and ``warm``: the API, a Redis job worker and the compiled kernels.

Only the standard library at module level (each command imports what it needs).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any


def cmd_serve(args: argparse.Namespace) -> int:
    from service.app import create_app
    from service.server import serve
    from workers.settings import get_settings, with_options

    settings = with_options(get_settings(), data_dir=args.data, redis_url=args.redis, workers=args.workers)
    if not is_loopback(args.host) and not settings.auth_enabled:
        print(
            f"segue: error: --host {args.host} would open the API to the network without tokens; set "
            "SEGUE_API_TOKENS (and SEGUE_ALLOWED_HOSTS) first: without tokens Segue is a single-user tool "
            "for this machine",
            file=sys.stderr,
        )
        return 2
    if args.imports:
        import_databases(settings, [Path(d) for d in args.imports])
    if not args.no_warm and not settings.redis_url:
        start_warming()  # the embedded workers run jobs: compile their kernels off the request path
    serve(create_app(settings), settings, args.host, args.port, args.log_level)
    return 0


def import_databases(settings: Any, folders: list[Path]) -> None:
    """``segue serve --import DIR``: put databases ``segue build`` wrote into the server's store, under
    the id the API gives the same clips and spec, held by every principal (the tokenless user and
    each ``SEGUE_API_TOKENS`` name). Raises ``workers.imports.ImportFailure`` naming a bad folder."""
    from service.deps import LOCAL, token_table
    from workers.imports import import_database_dir
    from workers.store import Store

    from ..summaries import count

    store = Store.from_settings(settings)
    owners = [LOCAL, *(name for name, _ in token_table(settings))]
    for folder in folders:
        info, new = import_database_dir(store, folder, owners)
        done = "imported" if new else "already held"
        print(
            f"segue: {done} {info.kind} database {info.id[:12]} ({count(len(info.clips), 'clip')}) "
            f"from {folder}",
            file=sys.stderr,
        )


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    import ipaddress

    if host.strip("[]").lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def cmd_worker(args: argparse.Namespace) -> int:
    from workers.redis_worker import serve
    from workers.settings import get_settings, with_options

    settings = with_options(get_settings(), redis_url=args.redis, data_dir=args.data, worker_name=args.name)
    if not settings.redis_url:
        print(
            "segue: error: a worker needs a Redis URL: give --redis URL or set SEGUE_REDIS_URL",
            file=sys.stderr,
        )
        return 2
    return serve(settings, warm=not args.no_warm)


def cmd_warm(args: argparse.Namespace) -> int:
    from engines.registry import warm_compiled
    from motion.jitcache import configure

    print(f"numba cache: {configure()}")
    warm_compiled(print, force=args.force)
    return 0


def start_warming() -> None:
    """``segue warm`` in a background process (niced, output to this terminal): the compiled
    kernels are ready before the first control job, without holding this process's GIL."""
    import os
    import subprocess

    def lower_priority() -> None:
        os.nice(5)

    subprocess.Popen(
        [sys.executable, "-m", "service.cli", "warm"],
        stdout=2,  # this process's standard error, whatever object sys.stderr is now
        stdin=subprocess.DEVNULL,
        preexec_fn=lower_priority if hasattr(os, "nice") else None,
    )
