"""The canonical schemas and their validator."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from navreplay.ingest.errors import TableValidationError
from navreplay.ingest.schema import SPECS, TableName, empty, from_columns, validate


def imu_columns(n: int = 5) -> dict[str, np.ndarray]:
    t = np.arange(n, dtype=np.int64) * 10_000_000
    cols: dict[str, np.ndarray] = {"t_ns": t}
    for axis in "xyz":
        cols[f"acc_{axis}_mps2"] = np.zeros(n)
        cols[f"gyro_{axis}_radps"] = np.zeros(n)
    cols["acc_z_mps2"] = np.full(n, -9.8)
    return cols


def obs_columns() -> dict[str, object]:
    t = np.array([0, 0, 0, 1_000_000_000, 1_000_000_000], dtype=np.int64)
    n = len(t)
    cols: dict[str, object] = {
        "t_ns": t,
        "sv": ["G01", "G05", "G12", "G01", "G05"],
        "pseudorange_m": np.full(n, 2.1e7),
    }
    for c in ("sat_x_m", "sat_y_m", "sat_z_m"):
        cols[c] = np.full(n, 1.5e7)
    return cols


def test_every_table_has_t_ns_first_and_a_key_starting_with_it() -> None:
    for name, ts in SPECS.items():
        assert ts.columns[0].name == "t_ns", name
        assert ts.key[0] == "t_ns", name
        assert ts.arrow_schema().field("t_ns").type == pa.int64()


def test_from_columns_builds_a_valid_table_in_canonical_order() -> None:
    table = from_columns("imu", imu_columns())
    assert table.column_names[0] == "t_ns"
    assert table.schema.field("acc_z_mps2").type == pa.float64()
    validate(TableName.IMU, table)


def test_nan_stays_a_value_and_absent_nullable_columns_become_null() -> None:
    cols = {
        "t_ns": np.array([0, 1], dtype=np.int64),
        "lat_deg": np.array([37.0, np.nan]),
        "lon_deg": np.array([127.0, 127.0]),
        "alt_m": np.array([60.0, 60.0]),
        "fix_type": np.array([3, 0]),
    }
    table = from_columns("gnss", cols)
    assert table.column("lat_deg").null_count == 0
    assert np.isnan(table.column("lat_deg").to_numpy()[1])
    assert table.column("vel_n_mps").null_count == 2
    assert table.column("num_sats").null_count == 2


def test_missing_required_column_is_named() -> None:
    cols = imu_columns()
    del cols["gyro_y_radps"]
    with pytest.raises(TableValidationError, match="gyro_y_radps") as err:
        from_columns("imu", cols)
    assert err.value.table == "imu"
    assert err.value.column == "gyro_y_radps"


def test_wrong_dtype_is_named() -> None:
    table = from_columns("imu", imu_columns())
    bad = table.set_column(1, "acc_x_mps2", table.column("acc_x_mps2").cast(pa.float32()))
    with pytest.raises(TableValidationError, match=r"acc_x_mps2.*wrong dtype float") as err:
        validate("imu", bad)
    assert err.value.column == "acc_x_mps2"


def test_unsafe_cast_is_refused() -> None:
    cols = {
        "t_ns": np.array([0.5, 1.0]),
        **{k: v[:2] for k, v in imu_columns().items() if k != "t_ns"},
    }
    with pytest.raises(TableValidationError, match="t_ns"):
        from_columns("imu", cols)


@pytest.mark.parametrize(
    ("times", "row", "word"),
    [
        ([0, 10, 10, 30], 2, "duplicate"),
        ([0, 10, 5, 30], 2, "unsorted"),
        ([0, 10, 20, 20], 3, "duplicate"),
    ],
)
def test_unsorted_or_duplicate_time_names_the_first_offending_row(
    times: list[int], row: int, word: str
) -> None:
    cols = imu_columns(4)
    cols["t_ns"] = np.array(times, dtype=np.int64)
    with pytest.raises(TableValidationError, match=word) as err:
        from_columns("imu", cols)
    assert err.value.row == row
    assert err.value.column == "t_ns"
    assert f"row {row}" in str(err.value)


def test_gnss_obs_key_is_time_then_satellite() -> None:
    validate("gnss_obs", from_columns("gnss_obs", obs_columns()))
    cols = obs_columns()
    cols["sv"] = ["G01", "G12", "G05", "G01", "G05"]
    with pytest.raises(TableValidationError, match="unsorted") as err:
        from_columns("gnss_obs", cols)
    assert (err.value.column, err.value.row) == ("sv", 2)
    cols["sv"] = ["G01", "G05", "G05", "G01", "G05"]
    with pytest.raises(TableValidationError, match="duplicate") as err:
        from_columns("gnss_obs", cols)
    assert err.value.row == 2


def test_null_in_non_nullable_column_names_row() -> None:
    table = from_columns("imu", imu_columns())
    arr = pa.array([0.0, None, 0.0, 0.0, 0.0], type=pa.float64())
    bad = table.set_column(table.schema.get_field_index("gyro_x_radps"), "gyro_x_radps", arr)
    with pytest.raises(TableValidationError, match="null") as err:
        validate("imu", bad)
    assert (err.value.column, err.value.row) == ("gyro_x_radps", 1)


def test_extra_columns_must_be_float64() -> None:
    cols = imu_columns()
    table = from_columns("imu", {**cols, "temp_c": np.zeros(5)})
    assert "temp_c" in table.column_names
    bad = table.append_column("label", pa.array(["a"] * 5))
    with pytest.raises(TableValidationError, match="label"):
        validate("imu", bad)


def test_chunk_must_follow_previous_chunk() -> None:
    table = from_columns("imu", imu_columns())
    with pytest.raises(TableValidationError, match="previous chunk"):
        validate("imu", table, previous_key=(0,))


def test_empty_table_has_full_schema() -> None:
    table = empty("gnss_obs")
    assert table.num_rows == 0
    assert "sat_clock_drift_mps" in table.column_names
    validate("gnss_obs", table)


def test_unknown_table_name_lists_known_ones() -> None:
    with pytest.raises(TableValidationError, match="known: imu, gnss"):
        validate("imus", from_columns("imu", imu_columns()))
