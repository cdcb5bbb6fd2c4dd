"""Annotation engine (Arikan, Forsyth & O'Brien 2003): database spec and request."""

from __future__ import annotations

from typing import Literal

from .bases import DatabaseSpecBase, JobRequestBase


class AnnotatedDatabaseSpec(DatabaseSpecBase):
    """Annotated database: labelled and unlabelled clips; labels propagate by SVM."""

    kind: Literal["annotated"] = "annotated"


class AnnotationRequest(JobRequestBase):
    """A motion following a do / don't / don't-care label timeline."""

    engine: Literal["annotations"] = "annotations"
