"""The service's settings: the one :class:`~workers.settings.Settings` class every Segue process
shares (defined with the runtime, which the API, the CLI and the workers all sit on).

``get_settings()`` reads the environment once per process; tests build a :class:`Settings` directly
and pass it to :func:`service.app.create_app` (or override :func:`service.deps.app_settings`).
"""

from workers.settings import MiB, Settings, get_settings, with_options

__all__ = ["MiB", "Settings", "get_settings", "with_options"]
