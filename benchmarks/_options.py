"""Benchmark options declared as data: a module's ``OPTIONS`` list, added by ``__main__``."""

from __future__ import annotations

import argparse
from dataclasses import dataclass


@dataclass(frozen=True)
class Option:
    """One command-line option of a benchmark (prefix its flag with the benchmark name).

    ``kind`` None makes it a ``store_true`` switch; otherwise the value's type, with ``default``.
    """

    flag: str
    help: str
    kind: type[int] | type[float] | None = None
    default: int | float | None = None

    def add_to(self, parser: argparse.ArgumentParser) -> None:
        if self.kind is None:
            parser.add_argument(self.flag, action="store_true", help=self.help)
        else:
            parser.add_argument(self.flag, type=self.kind, default=self.default, help=self.help)
