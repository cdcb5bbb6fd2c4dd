"""OpenAPI links: how the id in one response feeds the next request (``components.links``).

A client (or a stateful API fuzzer such as schemathesis) follows them to go from an upload to reading
it back, from a database build to its build job, and from a submitted job to its status, events,
result and report (the best result by id, from a job's status: the fuzzer varies the result
route's other query parameters, ``format``, ``mesh``, ``feet``, ``dancer``... on a real result).
"""

from __future__ import annotations

from typing import Any

# (source path, method, statuses) -> [(link name, target path, method, parameters)]
LINKS: list[tuple[str, str, tuple[str, ...], list[tuple[str, str, str, dict[str, str]]]]] = [
    (
        "/v1/clips",
        "post",
        ("200", "201"),
        [
            ("GetClip", "/v1/clips/{clip_id}", "get", {"clip_id": "$response.body#/id"}),
            ("DeleteClip", "/v1/clips/{clip_id}", "delete", {"clip_id": "$response.body#/id"}),
        ],
    ),
    (
        "/v1/files",
        "post",
        ("200", "201"),
        [
            ("GetFile", "/v1/files/{file_id}", "get", {"file_id": "$response.body#/id"}),
            ("DeleteFile", "/v1/files/{file_id}", "delete", {"file_id": "$response.body#/id"}),
        ],
    ),
    (
        "/v1/databases",
        "post",
        ("200", "202"),
        [
            ("GetDatabase", "/v1/databases/{db_id}", "get", {"db_id": "$response.body#/id"}),
            ("GetBuildJob", "/v1/jobs/{job_id}", "get", {"job_id": "$response.body#/build_job"}),
            ("BuildEvents", "/v1/jobs/{job_id}/events", "get", {"job_id": "$response.body#/build_job"}),
            ("DeleteDatabase", "/v1/databases/{db_id}", "delete", {"db_id": "$response.body#/id"}),
        ],
    ),
    (
        "/v1/jobs",
        "post",
        ("202",),
        [
            ("GetJob", "/v1/jobs/{job_id}", "get", {"job_id": "$response.body#/id"}),
            ("JobEvents", "/v1/jobs/{job_id}/events", "get", {"job_id": "$response.body#/id"}),
            ("JobResult", "/v1/jobs/{job_id}/result", "get", {"job_id": "$response.body#/id"}),
            ("JobReport", "/v1/jobs/{job_id}/report", "get", {"job_id": "$response.body#/id"}),
            ("CancelJob", "/v1/jobs/{job_id}/cancel", "post", {"job_id": "$response.body#/id"}),
        ],
    ),
    (
        "/v1/jobs/{job_id}",
        "get",
        ("200",),
        [  # the best result by its id: the result route's other query parameters are the fuzzer's
            (
                "BestResult",
                "/v1/jobs/{job_id}/result",
                "get",
                {"job_id": "$response.body#/id", "query.result": "$response.body#/result"},
            ),
            (
                "BestReport",
                "/v1/jobs/{job_id}/report",
                "get",
                {"job_id": "$response.body#/id", "query.result": "$response.body#/result"},
            ),
        ],
    ),
]


def add_links(schema: dict[str, Any]) -> None:
    """Add the links of :data:`LINKS` to the responses of an OpenAPI document (in place)."""
    paths = schema.get("paths", {})
    for source, method, statuses, targets in LINKS:
        operation = paths.get(source, {}).get(method)
        if operation is None:
            continue
        links = {}
        for name, path, target_method, parameters in targets:
            target = paths.get(path, {}).get(target_method)
            if target is None or "operationId" not in target:
                continue
            links[name] = {"operationId": target["operationId"], "parameters": dict(parameters)}
        for status in statuses:
            response = operation.get("responses", {}).get(status)
            if response is not None and links:
                response["links"] = dict(links)
