"""What a storage failure is, for every layer that reports it: a full disk, a read-only one, or a
store that cannot be reached.

The store raises :class:`OSError` from the file system (``ENOSPC``, ``EDQUOT``, ``EROFS``, ``EIO``,
an NFS mount's ``ESTALE``...); an object-store backend raises :class:`StoreUnavailable` (an
``OSError`` too) when its service does not answer. :func:`storage_problem` names the problem, and
the API answers it with 507 and that message (``service.errors``) instead of a 500.
"""

from __future__ import annotations

import errno

FULL = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""No room: the disk, the user's quota, or the largest file a process may write."""
READ_ONLY = frozenset({errno.EROFS})
UNREACHABLE = frozenset(
    {
        errno.EIO,
        errno.ESTALE,
        errno.ENOTCONN,
        errno.ETIMEDOUT,
        errno.EHOSTDOWN,
        errno.EHOSTUNREACH,
        errno.ENETUNREACH,
        errno.ECONNREFUSED,
        errno.ECONNRESET,
    }
)


class StoreUnavailable(OSError):
    """The store cannot be reached (an object store that does not answer, a lost network mount)."""

    def __init__(self, message: str) -> None:
        super().__init__(errno.EHOSTUNREACH, message)


def storage_problem(exc: BaseException) -> tuple[str, str] | None:
    """``(code, message)`` when ``exc`` (or an exception it was raised from) is a storage failure:
    ``storage_full``, ``storage_read_only`` or ``storage_unavailable``; None otherwise."""
    seen = 0
    current: BaseException | None = exc
    while current is not None and seen < 8:
        if isinstance(current, OSError):
            found = _classify(current)
            if found is not None:
                return found
        current = current.__cause__ or current.__context__
        seen += 1
    return None


def _classify(exc: OSError) -> tuple[str, str] | None:
    name = errno.errorcode.get(exc.errno or 0, "")
    if isinstance(exc, StoreUnavailable):
        return "storage_unavailable", f"the store cannot be reached ({exc.strerror}); try again later"
    if exc.errno in FULL:
        return (
            "storage_full",
            f"the server's storage is full ({name}): nothing was stored; free space by deleting "
            "clips, files, databases or jobs you no longer need (DELETE works on a full disk), or ask "
            "the operator",
        )
    if exc.errno in READ_ONLY:
        return "storage_read_only", f"the server's storage is read-only ({name}): nothing was stored"
    if exc.errno in UNREACHABLE:
        return "storage_unavailable", f"the server's storage cannot be reached ({name}); try again later"
    return None


class StoreTimeout(StoreUnavailable):
    """A store call did not answer within its time limit (``SEGUE_STORE_TIMEOUT_S``): the store
    stalls (an object store that accepts connections and never answers, a hung network mount)."""
