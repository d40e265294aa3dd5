"""Suite-wide settings.

The cold-compile helper of ``navreplay run`` (``pipeline.estimation.compile_helper``) is off in
the suite: its workers (pytest-xdist) already keep every core busy. The helper's own tests turn
it on where they need it.
"""

from __future__ import annotations

import os

os.environ.setdefault("NAVREPLAY_COMPILE_HELPER", "0")
