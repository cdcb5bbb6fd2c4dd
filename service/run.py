"""``python -m service.run [--host H] [--port P]``: serve the API (the same as ``segue serve``)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from .app import run
from .settings import get_settings

__all__ = ["main", "run"]


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the command line and serve until interrupted."""
    ap = argparse.ArgumentParser(prog="python -m service.run", description="Serve the Segue HTTP API.")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=8000)
    ap.add_argument("--log-level", default="info")
    args = ap.parse_args(argv)
    from .cli import is_loopback

    if not is_loopback(args.host) and not get_settings().auth_enabled:
        ap.error(f"--host {args.host} would open the API to the network without tokens; set SEGUE_API_TOKENS")
    run(args.host, args.port, get_settings(), args.log_level)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
