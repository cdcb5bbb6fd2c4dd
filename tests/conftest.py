"""Fixtures shared by every test package: a real S3-protocol server (``moto_server``)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.s3server import aws_environment, moto_server, new_bucket


@pytest.fixture(scope="session")
def s3_endpoint() -> Iterator[str]:
    """A ``moto_server`` (a real S3-protocol server) for the session, with the standard AWS
    variables pointing at it (so spawned workers find it as a deployment's would)."""
    with moto_server() as endpoint, aws_environment(endpoint):
        yield endpoint


@pytest.fixture
def s3_url(s3_endpoint: str) -> str:
    """``s3://<a fresh bucket>/segue``: a test's own empty object store."""
    return f"s3://{new_bucket(s3_endpoint)}/segue"
