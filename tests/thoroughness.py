"""How many examples the property-based (Hypothesis) tests try: the full count in CI
(``CI=true``) and with ``SEGUE_SLOW=1``, as tests/run.sh runs the slow tests; a quarter of it (at
least 50) in the default local run, which stays quick. Any counter-example Hypothesis finds is kept
in its database (``.hypothesis/``) and replayed first on the next run, whatever the count."""

from __future__ import annotations

import os

THOROUGH = os.environ.get("CI", "").lower() == "true" or os.environ.get("SEGUE_SLOW") == "1"


def examples(full: int) -> int:
    """``max_examples`` for a property whose full search tries ``full`` examples."""
    return full if THOROUGH else max(50, full // 4)
