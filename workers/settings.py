"""The one settings class of every Segue process: the API, the CLI and the workers.

Fields come from ``SEGUE_*`` environment variables (pydantic-settings), or from command-line options
passed as keyword arguments (which win). :func:`get_settings` reads the environment once per
process; everything else takes a :class:`Settings` and passes it down (the API's
:func:`service.app.create_app`, :func:`workers.redis_worker.run_worker`, the embedded backend).
Tests build a :class:`Settings` directly.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from motion.bvh import DEFAULT_MAX_FRAMES, DEFAULT_MAX_JOINTS, BvhLimits

from .budget import WorkLimits
from .redis_keys import CHUNK_SIZE, DEFAULT_PREFIX

MiB = 1 << 20


class Settings(BaseSettings):
    """Everything Segue's processes read from their environment (each field is ``SEGUE_<NAME>``):
    the API, the CLI and the workers share this one class, read once per process
    (:func:`get_settings`) and passed down; command-line options override fields
    (``Settings(**options)`` wins over the environment)."""

    model_config = SettingsConfigDict(env_prefix="SEGUE_", extra="ignore", frozen=True)

    data_dir: Path = Field(
        default=Path("./segue-data"),
        description="the store's directory (when store_url is unset), and this process's local cache",
    )
    store_url: str | None = Field(
        default=None,
        description="where everything durable lives: a directory or s3://bucket/prefix (endpoint and "
        "credentials from the standard AWS variables, AWS_ENDPOINT_URL for MinIO/Ceph); unset = data_dir",
    )
    disk_cache_mb: int = Field(
        default=8192, ge=1, description="databases downloaded from an object store kept on local disk, MiB"
    )
    redis_url: str | None = Field(
        default=None,
        repr=False,
        description="Redis job backend (unset = embedded pool): redis://[[user]:password@]host:port/db, "
        "rediss://... for TLS (?ssl_ca_certs=/path/ca.crt to trust a private CA; ssl_certfile and "
        "ssl_keyfile for client certificates), or unix:///path.sock; a password with URL-reserved "
        "characters is percent-encoded",
    )
    workers: int = Field(default=2, ge=1, le=256, description="embedded backend: worker processes")
    api_tokens: Annotated[tuple[str, ...], NoDecode] = Field(
        default=(),
        repr=False,
        description="comma-separated bearer tokens, each 'principal:token' (a bare token names the "
        "principal 'token-<first 8 hex digits of its sha256>'); empty = no auth, a single-user tool",
    )
    admins: Annotated[tuple[str, ...], NoDecode] = Field(
        default=(), description="comma-separated principals that may read, cancel and delete everything"
    )
    max_upload_bytes: int = Field(default=64 * MiB, ge=1, description="largest accepted clip upload")
    max_bvh_bytes: int | None = Field(
        default=None,
        ge=1,
        description="largest BVH text after gunzip (a gzip bomb stops here); default 4 x max_upload_bytes",
    )
    max_uploads: int = Field(
        default=16,
        ge=1,
        description="uploads (clips, files) received at once by one API process, each spooled to disk "
        "in 1 MiB chunks; one more is answered 503 too_many_uploads with Retry-After",
    )
    store_timeout_s: float = Field(
        default=10.0,
        gt=0,
        description="the API's bound on one store call (a streamed upload's: 10 x this); a store that "
        "does not answer in time is answered 503 store_unavailable with Retry-After, and /readyz says so",
    )
    max_json_bytes: int = Field(default=1 * MiB, ge=64, description="largest JSON request body, bytes")
    max_parses: int = Field(
        default=2, ge=1, le=256, description="request bodies (JSON, clip uploads) parsed at once"
    )
    allowed_hosts: Annotated[tuple[str, ...], NoDecode] = Field(
        default=("127.0.0.1", "localhost", "::1"),
        description="host names the server answers to (Host header; DNS-rebinding defence); '*' = any",
    )
    cors_origins: Annotated[tuple[str, ...], NoDecode] = Field(
        default=(), description="origins (scheme://host:port) allowed to call the API from other pages"
    )
    max_queued_jobs: int = Field(
        default=256, ge=1, description="unfinished jobs per principal (429 + Retry-After above it)"
    )
    max_sessions: int = Field(default=8, ge=1, description="live WebSocket sessions per principal")
    session_inbox: int = Field(default=64, ge=1, le=100_000, description="unread messages per live session")
    max_frames: int = Field(default=DEFAULT_MAX_FRAMES, ge=1, description="most frames in one clip")
    max_joints: int = Field(default=DEFAULT_MAX_JOINTS, ge=1, description="most joints in one clip")
    engine_plugins: str | None = Field(
        default=None, description="comma-separated plugin modules (engines.registry.load_plugins)"
    )
    ws_queue: int = Field(default=64, ge=2, le=100_000, description="per-WebSocket event queue bound")

    max_output_frames: int = Field(
        default=36_000, ge=1, description="output frames per character of one job (at the output rate)"
    )
    max_joint_frames: int = Field(
        default=10_000_000,
        ge=1,
        description="characters x output frames x joints of one job; also frames x joints of one uploaded "
        "clip (its header is checked against it before any row is read)",
    )
    max_job_memory_mb: int = Field(
        default=4096,
        ge=0,
        description="estimated memory of one job at submission; also the RSS at which "
        "a worker's supervisor stops a job (0: no limit)",
    )
    max_database_frames: int = Field(
        default=200_000,
        ge=1,
        description="frames of one database at its rate (all its clips), at submission, for kinds whose "
        "engine gives no build estimate (graph databases are bounded by max_build_cpu_s and "
        "max_job_memory_mb instead)",
    )
    max_build_cpu_s: float = Field(
        default=3600.0,
        ge=0,
        description="estimated CPU seconds of one database build, at submission (0: no limit)",
    )
    job_grace_s: float = Field(
        default=30.0,
        gt=0,
        description="a job running this long past its budget_s is stopped by its supervisor",
    )
    cancel_grace_s: float = Field(
        default=2.0, gt=0, description="a cancelled job still running this long after the cancel is killed"
    )
    max_job_seconds: float = Field(
        default=600.0, gt=0, description="estimated run time of one job (budget_s + assembly), seconds"
    )

    # -- the Redis runtime (``segue worker`` and the API's Redis backend) --------------------------
    redis_cache_url: str | None = Field(
        default=None,
        repr=False,
        description="a separate Redis (allkeys-lru) for the database cache, a URL as redis_url; "
        "unset = redis_url",
    )
    redis_prefix: str = Field(default=DEFAULT_PREFIX, min_length=1, description="Redis key prefix")
    worker_name: str | None = Field(
        default=None, min_length=1, description="worker consumer name, unique among live workers"
    )
    heartbeat_s: float = Field(default=1.0, gt=0, description="worker heartbeat period, seconds")
    heartbeat_ttl_s: float = Field(
        default=5.0, gt=0, description="a worker silent this long is dead (its jobs are reclaimed)"
    )
    max_deliveries: int = Field(default=3, ge=1, description="runs of a job before it is dead-lettered")
    block_ms: int = Field(default=1000, ge=1, description="XREADGROUP block time (bounds a stop's wait)")
    reclaim_idle_s: float = Field(
        default=30.0, gt=0, description="entries not refreshed this long are taken over (hung workers)"
    )
    refuse_backoff_s: float = Field(
        default=2.0,
        gt=0,
        description="a worker that refused a job of another version takes no job for this long "
        "(a worker of the job's version takes it meanwhile)",
    )
    cache_chunk_bytes: int = Field(default=CHUNK_SIZE, ge=1, description="database cache chunk size")
    engine_cache_mb: int = Field(
        default=2048,
        ge=0,
        description="loaded databases kept per engine process, MiB of their arrays (least recently "
        "used dropped first; 0: keep none)",
    )
    load_timeout_s: float = Field(
        default=300.0, gt=0, description="hard time limit of loading a job's database (not the job's budget)"
    )
    cache_max_object_mb: int = Field(
        default=64,
        ge=0,
        description="database objects up to this size are also cached in Redis for other workers (0: none)",
    )
    cancel_poll_s: float = Field(default=0.05, gt=0, description="how often a worker checks for a cancel")
    lock_ttl_s: float = Field(default=30.0, gt=0, description="a build lock's lifetime (refreshed)")
    hang_grace_s: float = Field(
        default=120.0, gt=0, description="a running job's entry is refreshed until 2 x budget_s + this"
    )
    build_timeout_s: float = Field(default=3600.0, gt=0, description="hard time limit of a database build")
    publish_retry_s: float = Field(
        default=300.0, gt=0, description="how long a worker retries an event while Redis is away"
    )
    event_archive_s: float = Field(
        default=1.0,
        gt=0,
        description="segue worker: a running job's events are copied to the store in batches at most "
        "this old (the history that survives a Redis restart without persistence)",
    )
    staged_max_age_s: float = Field(
        default=3600.0,
        gt=0,
        description="staged uploads (bytes a worker is to parse) older than this are removed as orphans "
        "by the sweep every worker and the embedded backend run every staged_sweep_s",
    )
    staged_sweep_s: float = Field(default=300.0, gt=0, description="how often the staged-upload sweep runs")
    log_level: str = Field(default="INFO", description="log level of segue worker")
    request_timeout_s: float = Field(
        default=30.0,
        gt=0,
        description="segue serve: a client must send a request's headers within this many seconds "
        "(of connecting, or of its previous response) and may not pause longer while sending a body; "
        "its connection is closed otherwise",
    )
    max_connections: int = Field(
        default=4096,
        ge=1,
        description="segue serve: open HTTP and WebSocket connections kept at once; one more is "
        "answered 503 and closed at once (the open-files limit is raised to fit, when allowed)",
    )
    max_connections_per_address: int = Field(
        default=512,
        ge=1,
        description="segue serve: open connections (HTTP and WebSocket) from one client address; one "
        "more is answered 503 too_many_connections and closed at once",
    )
    max_connections_per_principal: int = Field(
        default=256,
        ge=1,
        description="segue serve, with tokens: requests in progress and open WebSockets of one "
        "principal; one more is answered 503 too_many_connections (and closed) before its body is read",
    )
    request_deadline_s: float = Field(
        default=600.0,
        gt=0,
        description="segue serve: a request's headers and body must have arrived within this many "
        "seconds of its start (408 and the connection closed otherwise; the handler's own time, a "
        "long-poll or a WebSocket, does not count)",
    )
    min_body_rate: int = Field(
        default=1024,
        ge=0,
        description="segue serve: slowest request body, bytes per second: t seconds into a body at "
        "least min_body_rate x (t - body_rate_grace_s) bytes must have arrived (408 and the connection "
        "closed otherwise; time the server itself stops reading does not count; 0: no minimum)",
    )
    body_rate_grace_s: float = Field(
        default=10.0, gt=0, description="segue serve: seconds a body may send slowly before min_body_rate"
    )

    @field_validator("api_tokens", "admins", "allowed_hosts", "cors_origins", mode="before")
    @classmethod
    def _split_list(cls, value: Any) -> Any:
        """Accept ``"a,b"`` (the environment form) as well as a sequence."""
        if isinstance(value, str):
            return tuple(t.strip() for t in value.split(",") if t.strip())
        return value

    @property
    def auth_enabled(self) -> bool:
        """True when every API request needs a bearer token."""
        return bool(self.api_tokens)

    @property
    def work_limits(self) -> WorkLimits:
        """The work budget of one job (:mod:`workers.budget`)."""
        return WorkLimits(
            max_output_frames=self.max_output_frames,
            max_joint_frames=self.max_joint_frames,
            max_memory_bytes=self.max_rss_bytes,
            max_budget_s=self.max_job_seconds,
        )

    def work_limits_dict(self) -> dict[str, Any]:
        """The work limits as the settings name them (for error details)."""
        return {
            "max_output_frames": self.max_output_frames,
            "max_joint_frames": self.max_joint_frames,
            "max_job_memory_mb": self.max_job_memory_mb,
            "max_job_seconds": self.max_job_seconds,
        }

    @property
    def max_rss_bytes(self) -> int | None:
        """The memory limit of one job in bytes (None: no limit)."""
        return self.max_job_memory_mb * MiB if self.max_job_memory_mb else None

    @property
    def inflate_limit(self) -> int:
        """Largest BVH text after gunzip, bytes (``max_bvh_bytes``, default 4 x the upload limit)."""
        return self.max_bvh_bytes if self.max_bvh_bytes is not None else 4 * self.max_upload_bytes

    @property
    def bvh_limits(self) -> BvhLimits:
        """The reader limits for uploaded clips."""
        return BvhLimits(
            max_joints=self.max_joints,
            max_frames=self.max_frames,
            max_bytes=self.inflate_limit,
            max_joint_frames=self.max_joint_frames,
        )


@lru_cache
def get_settings() -> Settings:
    """The settings of this process, read from the environment once."""
    return Settings()


def with_options(settings: Settings, **options: Any) -> Settings:
    """``settings`` with the command-line options that were given (``None`` ones left out)."""
    given = {name: value for name, value in options.items() if value is not None}
    return Settings.model_validate({**settings.model_dump(), **given}) if given else settings
