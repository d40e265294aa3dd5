"""`navreplay synth`: the files of a dataset, opened by each format's reference reader."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import georinex
import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from navreplay.ingest.meta import read_meta
from navreplay.ingest.tables import read_table
from navreplay.pipeline.cli import main
from navreplay.pipeline.synth import DATASETS
from tests.ingest.navfile import read_gps_nav

REPO = Path(__file__).resolve().parents[3]
NAME = "seoul_campus_ccw"


def _params(tmp: Path, seed: int) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["synth"]["seed"] = seed
    data["synth"]["seoul_campus"].update(duration_s=90.0, stationary_s=15.0)
    path = tmp / f"params_{seed}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("synth")
    assert main(["synth", NAME, "--out", str(tmp / "a"), "--params", str(_params(tmp, 1))]) == 0
    return tmp


def test_the_dataset_files_are_written(out: Path) -> None:
    names = sorted(p.name for p in (out / "a").iterdir())
    assert names == ["reference", *(f"{NAME}.{x}" for x in ("bag", "mcap", "nav", "obs"))]
    ref = out / "a" / "reference"
    assert sorted(p.name for p in ref.iterdir()) == [
        "gnss.parquet",
        "gnss_obs.parquet",
        "imu.parquet",
        "meta.json",
        "truth.parquet",
    ]
    meta = read_meta(ref)
    assert meta.dataset == NAME
    assert meta.time_base == "gps"
    assert meta.tables == {
        "gnss": 91,
        "gnss_obs": meta.tables["gnss_obs"],
        "imu": 9001,
        "truth": 9001,
    }
    assert {s.name for s in meta.sources} == {f"{NAME}.{x}" for x in ("mcap", "bag", "obs", "nav")}
    assert meta.sensors.lever_arm_m == (0.3, 0.0, -1.5)


def test_every_file_opens_with_its_reference_reader(out: Path) -> None:
    ref = out / "a" / "reference"
    imu = read_table(ref / "imu.parquet", "imu").table
    obs = read_table(ref / "gnss_obs.parquet", "gnss_obs").table
    with (out / "a" / f"{NAME}.mcap").open("rb") as fh:
        summary = make_reader(fh).get_summary()
        assert summary is not None
        assert summary.statistics is not None
        counts = {
            ch.topic: summary.statistics.channel_message_counts[cid]
            for cid, ch in summary.channels.items()
        }
    assert counts == {"/imu/data": 9001, "/gps/fix": 91, "/gps/vel": 91, "/truth": 9001}
    with AnyReader([out / "a" / f"{NAME}.bag"]) as bag:
        conn = next(c for c in bag.connections if c.topic == "/imu/data")
        msgs: list[Any] = [bag.deserialize(raw, conn.msgtype) for _, _, raw in bag.messages([conn])]
    assert len(msgs) == 9001
    np.testing.assert_array_equal(
        [-m.angular_velocity.z for m in msgs], imu.column("gyro_z_radps").to_numpy()
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        ds = georinex.load(out / "a" / f"{NAME}.obs")
    assert int(np.isfinite(ds["C1C"].values).sum()) == obs.num_rows
    assert ds.sizes["time"] == 91
    eph = read_gps_nav(out / "a" / f"{NAME}.nav")
    assert sorted(set(eph.prn.tolist())) == list(range(1, 25))


def test_same_seed_same_bytes_other_seed_other_noise(out: Path) -> None:
    assert main(["synth", NAME, "--out", str(out / "b"), "--params", str(_params(out, 1))]) == 0
    assert main(["synth", NAME, "--out", str(out / "c"), "--params", str(_params(out, 2))]) == 0
    for ext in ("mcap", "bag", "obs", "nav"):
        a, b, c = ((out / d / f"{NAME}.{ext}").read_bytes() for d in "abc")
        assert a == b, ext
        if ext != "nav":  # seed 2 draws other satellite clocks too, but check the noisy ones
            assert a != c, ext
    for table in ("imu", "truth", "gnss", "gnss_obs"):
        assert (out / "a" / "reference" / f"{table}.parquet").read_bytes() == (
            out / "b" / "reference" / f"{table}.parquet"
        ).read_bytes()


def test_unknown_and_unbuilt_datasets_exit_honestly(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    params = str(REPO / "params.yaml")
    assert main(["synth", "no_such_dataset", "--out", str(tmp_path), "--params", params]) == 2
    # a dataset listed in params.yaml without a synthesizer is "not built yet"
    monkeypatch.delitem(DATASETS, "seoul_campus_cw")
    assert main(["synth", "seoul_campus_cw", "--out", str(tmp_path), "--params", params]) == 3
    assert not any(tmp_path.iterdir())
