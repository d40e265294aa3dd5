"""The files a report is rendered from: the error a malformed one raises
(``ReportInputError``) and the JSON reader that raises it, shared by ``inputs`` (runs and
the ingest report), ``experiments`` (experiment directories) and ``summary``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from navreplay.pipeline.errors import PipelineError


class ReportInputError(PipelineError):
    """A file a report is rendered from is malformed; names the file and the problem."""

    def __init__(self, path: Path, reason: str) -> None:
        self.path = path
        self.reason = reason
        super().__init__(f"{path}: {reason}")


def read_json(path: Path) -> Any:
    """Parse a JSON file; a malformed one is a ``ReportInputError`` naming it."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ReportInputError(path, f"cannot read: {err.strerror}") from err
    except ValueError as err:
        raise ReportInputError(path, f"not valid JSON: {err}") from err
