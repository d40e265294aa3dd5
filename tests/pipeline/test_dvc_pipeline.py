"""dvc.yaml: coherent with params.yaml, and a filter's params re-run only that filter's runs.

The second test copies dvc.yaml and params.yaml into a scratch DVC repository, stands in a
placeholder for every dependency and output, records them in dvc.lock (``dvc commit``, so no
stage runs), then changes one parameter of ``tc_ukf`` and asks ``dvc status`` what changed.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from navreplay.pipeline.params import load_params

REPO = Path(__file__).resolve().parents[2]


def test_summarize_stage_lists_every_dataset_report() -> None:
    spec = yaml.safe_load((REPO / "dvc.yaml").read_text())
    datasets = load_params(REPO / "params.yaml").datasets
    stage = spec["stages"]["summarize"]
    deps = [d for d in stage["deps"] if d.startswith("reports/")]
    assert deps == [f"reports/{d}/tables" for d in datasets]
    assert all(f"reports/{d} " in stage["cmd"] for d in datasets)


def _dvc(root: Path, *args: str) -> str:
    done = subprocess.run(
        [str(Path(shutil.which("dvc") or REPO / ".venv/bin/dvc")), *args],
        cwd=root,
        capture_output=True,
        text=True,
        check=False,
        env={"DVC_NO_ANALYTICS": "1", "PATH": "/usr/bin:/bin", "HOME": str(root)},
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.slow
def test_changing_one_filter_reruns_only_its_runs_and_then_the_reports(tmp_path: Path) -> None:
    from dvc.repo import Repo

    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    shutil.copy(REPO / "dvc.yaml", tmp_path)
    shutil.copy(REPO / "params.yaml", tmp_path)
    _dvc(tmp_path, "init", "-q")
    with Repo(str(tmp_path)) as repo:
        stages = list(repo.index.stages)
        for st in stages:
            for d in st.deps:
                p = Path(d.fs_path)
                if p.name != "params.yaml" and not p.exists():
                    target = p if p.suffix else p / "placeholder"
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_text("x")
            for o in st.outs:
                p = Path(o.fs_path)
                target = p if p.suffix else p / "placeholder"
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(st.addressing)
    _dvc(tmp_path, "commit", "-f", "-q")
    assert "up to date" in _dvc(tmp_path, "status")
    params = (tmp_path / "params.yaml").read_text()
    changed = params.replace("      alpha: 0.99", "      alpha: 0.98", 1)
    assert changed != params
    (tmp_path / "params.yaml").write_text(changed)
    status = yaml.safe_load(_dvc(tmp_path, "status", "--json"))
    prm = load_params(REPO / "params.yaml")
    # the ukf section is shared by tc_ukf and tc_ukf_nhc (a YAML anchor): both re-run
    ukfs = [f for f in ("tc_ukf", "tc_ukf_nhc") if f in prm.run.filters]
    expected = {f"run@{d}-{f}" for d in prm.run.datasets for f in ukfs}
    expected |= {
        f"montecarlo@{d}-{f}" for d in prm.run.datasets for f in ukfs if f in prm.outages.filters
    }
    # and the experiments that run them (the robustness sweep runs every INS filter)
    stages = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]
    expected |= {
        name
        for name, stage in stages.items()
        if "foreach" not in stage
        and any(p in {f"filters.{f}" for f in ukfs} | {"filters"} for p in stage.get("params", []))
    }
    assert "experiment_robustness" in expected
    assert set(status) == expected
    # downstream of them (stages whose deps hold their outputs): the outage tables, the
    # reports of those datasets, the summary
    with Repo(str(tmp_path)) as repo:
        graph = repo.index.graph  # an edge A -> B: stage A depends on stage B
        by_name = {st.addressing.split(":")[-1]: st for st in graph.nodes}
        todo = [by_name[name] for name in expected]
        after: set[str] = set()
        while todo:
            for st in graph.predecessors(todo.pop()):
                name = st.addressing.split(":")[-1]
                if name not in after:
                    after.add(name)
                    todo.append(st)
    datasets = set(prm.run.datasets)
    assert after == {f"report@{d}" for d in datasets} | {f"outages@{d}" for d in datasets} | {
        "summarize"
    }


def test_a_recorded_dataset_gets_ingest_run_and_report_stages(tmp_path: Path) -> None:
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    shutil.copy(REPO / "dvc.yaml", tmp_path)
    text = (REPO / "params.yaml").read_text()
    text = text.replace("recorded: []", "recorded: [my_rig]", 1)
    text = text.replace("  datasets: [seoul_campus_cw, seoul_campus_ccw]",
                        "  datasets: [seoul_campus_cw, seoul_campus_ccw, my_rig]", 1)  # fmt: skip
    (tmp_path / "params.yaml").write_text(text)
    load_params(tmp_path / "params.yaml")  # still valid
    _dvc(tmp_path, "init", "-q")
    names = {line.split()[0] for line in _dvc(tmp_path, "stage", "list").splitlines()}
    assert {"ingest_recorded@my_rig", "report_recorded@my_rig"} <= names
    assert "run@my_rig-tc_ukf" in names
    assert not any(n.startswith("synth@my_rig") for n in names)
