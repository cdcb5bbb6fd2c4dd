"""Control-by-example engine (Hsu, Gentry & Popović 2004): database spec and request."""

from __future__ import annotations

from typing import Literal

from .bases import DatabaseSpecBase, JobRequestBase


class ControlDatabaseSpec(DatabaseSpecBase):
    """Control-by-example database: synchronized (control, target) example pairs."""

    kind: Literal["control"] = "control"


class ControlRequest(JobRequestBase):
    """A target motion driven by a control motion."""

    engine: Literal["control"] = "control"
