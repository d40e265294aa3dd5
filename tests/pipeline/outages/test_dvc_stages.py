"""The run and Monte Carlo stages of dvc.yaml depend on their own filter's params only."""

from __future__ import annotations

import os

from tests.pipeline.scenarios.drives import REPO, params


def test_each_filter_cell_depends_on_its_own_filter_params_only() -> None:
    os.environ.setdefault("DVC_NO_ANALYTICS", "1")
    from dvc.repo import Repo

    with Repo(str(REPO)) as repo:
        stages = {s.name: s for s in repo.index.stages}
    p = params()
    cells = [(d, f) for d in p.run.datasets for f in p.run.filters]
    cells_mc = [(d, f) for d in p.run.datasets for f in p.outages.filters]
    for prefix, grid in (("run", cells), ("montecarlo", cells_mc)):
        for dataset, name in grid:
            stage = stages[f"{prefix}@{dataset}-{name}"]
            keys = [k for d in stage.deps if hasattr(d, "params") for k in d.params]
            assert [k for k in keys if k.startswith("filters")] == [f"filters.{name}"]
            assert "outages" not in keys  # only the keys that change a filter's windows
            (out,) = stage.outs
            assert str(out.def_path).endswith(f"{dataset}/{prefix.replace('run', 'runs')}/{name}")
    for dataset in p.run.datasets:
        outs = [str(o.def_path) for o in stages[f"outages@{dataset}"].outs]
        assert f"datasets/{dataset}/experiments/sat_reduction.csv" in outs
