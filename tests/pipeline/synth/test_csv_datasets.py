"""tractor_straight and car_speed_ramp as CSV logs: descriptors, pandas, reproducibility."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from navreplay.ingest.config import CsvSource, load_dataset_config
from navreplay.ingest.meta import read_meta
from navreplay.ingest.tables import read_table
from navreplay.pipeline.params import load_params
from navreplay.pipeline.synth import car, tractor_log
from navreplay.pipeline.synth.tractor import TractorStraightParams

REPO = Path(__file__).resolve().parents[3]

Writer = Callable[[int, Path], list[Path]]
CASES: dict[str, Writer] = {
    "tractor_straight": lambda seed, out: tractor_log.write(
        TractorStraightParams(duration_s=20.0), seed, out
    ),
    "car_speed_ramp": lambda seed, out: car.write(
        dataclasses.replace(car.CarSpeedRampParams(), ramp_s=40.0, hold_s=5.0), seed, out
    ),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def written(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> tuple[str, Path]:
    dataset: str = request.param
    out = tmp_path_factory.mktemp(dataset) / "raw"
    CASES[dataset](5, out)
    return dataset, out


def load_with_pandas(source: CsvSource, raw_dir: Path) -> pd.DataFrame:
    """What a CSV reader following the descriptor does: map, scale, convert the time."""
    df = pd.read_csv(raw_dir / Path(source.path).name, comment=source.comment)
    out = pd.DataFrame({"t_ns": df[source.time_column].astype("int64") * 1000})
    for canonical, column in source.columns.items():
        out[canonical] = df[column] * source.scale.get(canonical, 1.0)
    return out


def test_descriptor_csv_mappings_reproduce_the_reference_tables(written: tuple[str, Path]) -> None:
    dataset, raw = written
    cfg = load_dataset_config(REPO / "datasets" / dataset / "dataset.yaml")
    assert cfg.time_base == "utc"
    assert set(cfg.required) == {"vehicle", "gnss", "truth"}
    assert {s.table for s in cfg.csv} == {"vehicle", "gnss", "truth"}
    for source in cfg.csv:
        assert source.time_unit == "us"
        df = load_with_pandas(source, raw)
        ref = read_table(raw / "reference" / f"{source.table}.parquet", source.table).table
        mapped = set(df.columns) - {"t_ns"}
        # every provided (not all-null) reference column is mapped, and nothing else
        provided = {c for c in ref.column_names if ref[c].null_count < ref.num_rows}
        assert mapped == provided - {"t_ns"}
        np.testing.assert_array_equal(df["t_ns"].to_numpy(), ref["t_ns"].to_numpy())
        for name in mapped:
            got, want = df[name].to_numpy(), ref[name].to_numpy(zero_copy_only=False)
            if source.table == "truth":  # truth is exact in the reference, 1e-10 in the file
                np.testing.assert_allclose(got, want, rtol=0, atol=1e-9, err_msg=name)
            else:  # measurements are exactly what the file holds
                np.testing.assert_array_equal(got, want, err_msg=name)


def test_same_seed_gives_byte_identical_files_another_seed_other_noise(
    written: tuple[str, Path], tmp_path: Path
) -> None:
    dataset, raw = written
    again = CASES[dataset](5, tmp_path / "again")
    for path in again:
        assert path.read_bytes() == (raw / path.relative_to(tmp_path / "again")).read_bytes()
    other = CASES[dataset](6, tmp_path / "other")
    names = [p.name for p in other if p.suffix == ".csv"]
    assert len(names) == 3
    for name in names:
        # the first line is a comment naming the seed; the truth does not depend on it
        ours = (raw / name).read_text().splitlines()[1:]
        theirs = (tmp_path / "other" / name).read_text().splitlines()[1:]
        assert (ours != theirs) is (not name.endswith("truth.csv")), name


def test_write_dataset_takes_its_section_of_params_and_replaces_the_folder(tmp_path: Path) -> None:
    synth = load_params(REPO / "params.yaml").synth
    short = dataclasses.replace(
        synth, tractor_straight=dataclasses.replace(synth.tractor_straight, duration_s=2.0)
    )
    out = tmp_path / "raw"
    out.mkdir()
    (out / "stale.csv").write_text("left over from another run\n")
    files = tractor_log.write_dataset("tractor_straight", short, out)
    assert sorted(p.name for p in out.iterdir()) == [
        "reference",
        "tractor_straight_gnss.csv",
        "tractor_straight_truth.csv",
        "tractor_straight_vehicle.csv",
    ]
    assert all(p.exists() for p in files)
    assert read_meta(out / "reference").tables == {"gnss": 101, "truth": 101, "vehicle": 101}
    with pytest.raises(ValueError, match="not 'car_speed_ramp'"):
        tractor_log.write_dataset("car_speed_ramp", short, out)
