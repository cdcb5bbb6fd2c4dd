"""One ``APIRouter`` per resource."""

from . import clips, databases, events, health, jobs

__all__ = ["clips", "databases", "events", "health", "jobs"]
