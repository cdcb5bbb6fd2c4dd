"""``python -m service.cli``: the ``segue`` command."""

from __future__ import annotations

from . import main

raise SystemExit(main())
