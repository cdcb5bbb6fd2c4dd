"""What "the same version" means between an API and its workers.

Two stamps travel with every job the API queues (:mod:`workers.redis_queue`), and a worker runs a
job only when both equal its own:

* :data:`JOB_FORMAT`, the job format: the layout of the queue's entries, payloads and events and
  of the store's objects that API and workers share. It changes (by one) whenever a release
  changes any of them; a worker of another format could not read the job correctly.
* the package version (:func:`package_version`, ``segue``'s installed version): the engines and
  their defaults. The same request and seed give byte-identical results only with the same code,
  so a job is run by the version that accepted it.

A worker that receives a job of another version refuses it with an error log naming both versions
and gives it back to the queue (it stays queued for a worker of the right version); the API's
``/healthz`` lists every worker's version. Upgrade the API and its workers together.
"""

from __future__ import annotations

from functools import lru_cache

JOB_FORMAT = 2
"""1: one jobs stream (before per-principal queues); 2: per-principal waiting lists, stamped entries,
event batches in the store."""


@lru_cache
def package_version() -> str:
    """The installed ``segue`` package's version (``0+unknown`` when it is not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("segue")
    except PackageNotFoundError:
        return "0+unknown"


def stamp() -> dict[str, str]:
    """The version fields the API writes into every queued job."""
    return {"format": str(JOB_FORMAT), "version": package_version()}


def describe(fields: dict[str, str]) -> str:
    """A job's stamps as a log names them (``segue 0.1.0, job format 2``)."""
    return f"segue {fields.get('version') or '(none)'}, job format {fields.get('format') or '1'}"


def mismatch(fields: dict[str, str]) -> str | None:
    """Why a worker of this version must not run the job whose entry is ``fields`` (None: it may)."""
    if fields.get("format") == str(JOB_FORMAT) and fields.get("version") == package_version():
        return None
    mine = describe({"format": str(JOB_FORMAT), "version": package_version()})
    return f"it was queued by an API of {describe(fields)}; this worker is {mine}"
