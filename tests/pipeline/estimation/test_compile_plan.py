"""compile_helper's plan (``compile_plan.json``) is what cold kernel compiles compile."""

from __future__ import annotations

import json

import pytest

from pipeline.estimation import compile_helper as ch


@pytest.mark.slow
@pytest.mark.parametrize("name", ["lc_ekf", "tc_ukf"])
def test_the_plan_is_what_a_cold_compile_compiles(name: str) -> None:
    filters, _ = ch.load_plan()
    raw = json.loads(ch.PLAN_PATH.read_text())
    recorded = ch.record_cold(name)
    assert recorded == raw["kernels"][filters[name]], (
        f"compile_plan.json is stale for {name}: run `{ch.WRITE_COMMAND}`"
    )
