"""The suite's order: files holding a ``slow`` test first.

``make test`` spreads whole files over two workers (pytest-xdist ``--dist loadfile``), handed
out in this order (``--no-loadscope-reorder``; xdist's default puts the files with the most
tests first). The files of few but long tests then came last: the wheel test (a cold compile
in a fresh environment, 1-2 minutes) ran alone while the other worker idled. Started
first, the long files overlap each other and the short ones fill the end. The sort is stable:
each file's tests stay together and in their order.
"""

from __future__ import annotations

import pytest


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    slow = {item.path for item in items if item.get_closest_marker("slow") is not None}
    items.sort(key=lambda item: item.path not in slow)
