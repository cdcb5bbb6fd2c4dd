"""moto's S3 server (``moto_server``) with each request handled whole before the next one starts.

Run as ``python tests/moto_atomic.py -H HOST -p PORT`` (what :func:`tests.s3server.moto_server`
and ``bench/faults.py`` start).

moto checks a conditional PUT's ``If-Match`` / ``If-None-Match`` and then writes, with no lock
between the two (``moto/s3/responses.py``, ``put_object``): a thread switch between them lets two
concurrent compare-and-swaps on one object both succeed. S3 and MinIO make each conditional write
atomic, and Segue's holders (:mod:`workers.holders`) rely on it. A race of a delete against
another principal's upload (``tests/workers/test_holders.py``, S3) failed once at load 5 and never
in reruns; a direct race of 1,500 four-way compare-and-swaps on moto found no double success, so
this is a possible cause, not a proven one. One lock around moto's application gives the tests
S3's guarantee either way; requests are then served one at a time, which the tests' small
objects do not notice.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Callable, Iterable
from typing import Any

from moto.moto_server.werkzeug_app import DomainDispatcherApplication, create_backend_app
from werkzeug.serving import run_simple


class Serialized:
    """A WSGI application that runs ``app`` for one request at a time, its response whole."""

    def __init__(self, app: Callable[..., Iterable[bytes]]) -> None:
        self.app = app
        self.lock = threading.Lock()

    def __call__(self, environ: dict[str, Any], start_response: Callable[..., Any]) -> list[bytes]:
        with self.lock:
            return list(self.app(environ, start_response))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-H", "--host", default="127.0.0.1")
    parser.add_argument("-p", "--port", type=int, required=True)
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    app = DomainDispatcherApplication(create_backend_app)
    run_simple(args.host, args.port, Serialized(app), threaded=True)


if __name__ == "__main__":
    main()
