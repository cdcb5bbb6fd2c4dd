"""Segue's public contract: pydantic models shared by the HTTP API, the CLI, the workers and the browser.

One source of truth: the OpenAPI document is generated from these models, and ``segue build`` /
``segue synth`` validate their JSON files with the same classes.
"""

from .clips import ClipInfo, ClipSource, LabelRange
from .common import SCHEMA_VERSION, ErrorBody, ErrorResponse
from .databases import DatabaseInfo, DatabaseStatus
from .events import EventType, JobEvent
from .jobs import JobInfo, JobStatus
from .reports import ProvenanceEntry, Report

__all__ = [
    "SCHEMA_VERSION",
    "ClipInfo",
    "ClipSource",
    "DatabaseInfo",
    "DatabaseStatus",
    "ErrorBody",
    "ErrorResponse",
    "EventType",
    "JobEvent",
    "JobInfo",
    "JobStatus",
    "LabelRange",
    "ProvenanceEntry",
    "Report",
]
