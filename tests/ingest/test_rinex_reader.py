"""RINEX observation + navigation files into ``gnss_obs``: the fast parser against georinex,
the satellite states against the broadcast orbits, and damaged or odd files."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from navreplay.ingest.api import IngestOptions, ingest
from navreplay.ingest.damage import DamageLog
from navreplay.ingest.errors import CorruptLogError, IngestError, UnsupportedFormatError
from navreplay.ingest.gnss.ephemeris import C_MPS, Ephemeris, select, transmit_state
from navreplay.ingest.gnss.rinexobs import from_georinex, read_obs
from navreplay.ingest.gpstime import NS_PER_S, NS_PER_WEEK, calendar_from_gps
from navreplay.ingest.writers import rinex

from .gnssfiles import (
    antenna_ecef,
    assert_obs_match,
    short_drive,
    station,
    write_obs2,
    write_obs3_mixed,
    write_pair,
)
from .navfile import read_gps_nav


@pytest.fixture(scope="module")
def synth() -> Any:
    return short_drive()


def _fast_rows(path: Path) -> tuple[Any, Any, DamageLog]:
    damage = DamageLog(path, strict=False)
    head, sig, scan, chunks = read_obs(path, "obs", damage, chunk_rows=40)  # several chunks
    parts = list(chunks)
    cat = {
        name: np.concatenate([getattr(p, name) for p in parts])
        for name in ("t_ns", "prn", "pseudorange_m", "doppler_hz", "strength")
    }
    return (head, sig), (scan, cat), damage


@pytest.mark.parametrize("kind", ["rinex3", "rinex3_mixed", "rinex2"])
def test_the_fast_parser_reads_exactly_what_georinex_reads(
    synth: Any, tmp_path: Path, kind: str
) -> None:
    path = tmp_path / "drive.obs"
    n_gps = synth.tables["gnss_obs"].num_rows
    counts = {"gps": n_gps}
    if kind == "rinex3":
        write_pair(tmp_path, synth)
    elif kind == "rinex3_mixed":  # no flag-4 event: georinex stops reading at one (below)
        counts = write_obs3_mixed(path, synth, header_event=False)
    else:
        counts = write_obs2(path, synth)
    (head, sig), (scan, fast), damage = _fast_rows(path)
    ref = from_georinex(path, head, sig)
    order = np.lexsort((ref.prn, ref.t_ns))
    assert fast["t_ns"].size == counts["gps"] == n_gps
    np.testing.assert_array_equal(fast["t_ns"], ref.t_ns[order])
    np.testing.assert_array_equal(fast["prn"], ref.prn[order])
    for ours, theirs in (
        ("pseudorange_m", ref.pseudorange_m),
        ("doppler_hz", ref.doppler_hz),
        ("strength", ref.strength),
    ):
        np.testing.assert_array_equal(fast[ours], theirs[order], err_msg=ours)
    assert scan.rows_by_system.get("GLONASS", 0) == counts.get("glonass", 0)
    assert scan.rows_by_system.get("Galileo", 0) == counts.get("galileo", 0)
    assert int(np.isnan(fast["doppler_hz"]).sum()) == counts.get("blank_doppler", 0)
    assert scan.skipped.events_skipped == counts.get("events", 0)
    assert not damage.defects


def test_header_records_inside_the_body_are_skipped_and_reading_goes_on(
    synth: Any, tmp_path: Path
) -> None:
    counts = write_obs3_mixed(tmp_path / "drive.obs", synth, header_event=True)
    (head, sig), (scan, fast), damage = _fast_rows(tmp_path / "drive.obs")
    assert fast["t_ns"].size == counts["gps"]
    assert scan.skipped.events_skipped == counts["events"] == 2
    assert not damage.defects
    # georinex 1.16 silently stops at such an event (a canary: tell us when it no longer does)
    assert len(from_georinex(tmp_path / "drive.obs", head, sig)) < counts["gps"]


def test_obs_and_nav_give_the_synthesizers_satellite_states(synth: Any, tmp_path: Path) -> None:
    obs, nav = write_pair(tmp_path / "raw", synth)
    result = ingest([obs, nav], tmp_path / "out")
    assert result.tables == {"gnss_obs": synth.tables["gnss_obs"].num_rows}
    assert result.report["time_base"]["base"] == "gps"
    got = pq.read_table(tmp_path / "out" / "gnss_obs.parquet")
    ref = synth.tables["gnss_obs"]
    assert_obs_match(ref, got)
    counters = result.report["tables"]["gnss_obs"]["counters"]
    assert counters["no_ephemeris"] == counters["no_receiver_position"] == 0
    assert counters["epochs_solved"] == np.unique(ref["t_ns"].to_numpy()).size
    # RINEX 2.11 of the same observations gives the same table
    (tmp_path / "raw2").mkdir()
    write_obs2(tmp_path / "raw2" / "drive.obs", synth)
    shutil.copy(nav, tmp_path / "raw2" / "drive.nav")
    r2 = ingest([tmp_path / "raw2" / "drive.obs", tmp_path / "raw2" / "drive.nav"], tmp_path / "o2")
    got2 = pq.read_table(tmp_path / "o2" / "gnss_obs.parquet")
    assert got2.equals(got)
    assert r2.report["files"][0]["counters"]["rows_GLONASS_excluded"] == 6 * len(
        np.unique(ref["t_ns"].to_numpy())
    )


def test_satellite_states_are_the_broadcast_orbits_recomputed_independently(
    synth: Any, tmp_path: Path
) -> None:
    # georinex reads the navigation file; ingest.gnss.ephemeris evaluates it at the receive
    # time less the receiver clock, seen from the receiver position solved by ingest.
    obs, nav = write_pair(tmp_path / "raw", synth)
    ingest([obs, nav], tmp_path / "out")
    got = pq.read_table(tmp_path / "out" / "gnss_obs.parquet")
    eph = read_gps_nav(nav)
    t = got["t_ns"].to_numpy()
    prn = np.array([int(s[1:]) for s in got["sv"].to_pylist()])
    truth = synth.tables["truth"]
    rows = np.searchsorted(truth["t_ns"].to_numpy(), t)
    clock = truth["clock_bias_m"].to_numpy()[rows]
    ant = antenna_ecef(synth, rows)
    state = transmit_state(eph, select(eph, prn, t), t, ant, rx_offset_s=-clock / C_MPS)
    sat = np.stack([got[f"sat_{a}_m"].to_numpy() for a in "xyz"], axis=1)
    np.testing.assert_allclose(sat, state.sat.pos_m, rtol=0, atol=2e-4)
    el = got["elevation_deg"].to_numpy()
    assert el.min() >= 10.0 - 1e-6
    assert el.max() <= 90.0
    az = got["azimuth_deg"].to_numpy()
    assert az.min() >= 0.0
    assert az.max() < 360.0


# ------------------------------------------------------------------------------ bad input
def test_a_truncated_observation_file_keeps_its_complete_epochs(synth: Any, tmp_path: Path) -> None:
    obs, nav = write_pair(tmp_path, synth)
    text = obs.read_text()
    cut = text.index("G10", len(text) // 2) + 8  # inside a satellite record
    obs.write_text(text[:cut])
    lines = text[:cut].splitlines()
    last_epoch = max(i for i, ln in enumerate(lines, start=1) if ln.startswith(">"))
    body = lines.index(next(ln for ln in lines if "END OF HEADER" in ln)) + 1
    complete = sum(1 for ln in lines[body : last_epoch - 1] if ln.startswith("G"))
    result = ingest([obs, nav], tmp_path / "out")
    assert result.tables["gnss_obs"] == complete
    (defect,) = result.report["files"][0]["defects"]
    assert defect["kind"] == "truncated"
    assert defect["offset"] == last_epoch
    assert result.report["files"][0]["completeness"] == ["truncated"]
    with pytest.raises(CorruptLogError, match=rf"drive.obs: line {last_epoch}: .*cut by the end"):
        ingest([obs, nav], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()


def test_garbage_lines_are_skipped_with_their_line_numbers(synth: Any, tmp_path: Path) -> None:
    obs, nav = write_pair(tmp_path, synth)
    lines = obs.read_text().splitlines(keepends=True)
    epochs = [i for i, ln in enumerate(lines) if ln.startswith(">")]
    lines.insert(epochs[5], "#### logger restarted ####\n")  # between epochs
    sat = epochs[9] + 2  # a satellite record replaced (index shifted by the insertion)
    lines[sat] = "?? garbage that is not a satellite record\n"
    obs.write_text("".join(lines))
    result = ingest([obs, nav], tmp_path / "out")
    assert result.tables["gnss_obs"] == synth.tables["gnss_obs"].num_rows - 1
    offsets = sorted(d["offset"] for d in result.report["files"][0]["defects"])
    assert offsets == [epochs[5] + 1, sat + 1]
    assert result.report["files"][0]["completeness"] == ["bad_data_skipped"]


@pytest.mark.parametrize(
    ("edit", "error", "where"),
    [
        (lambda t: t.replace("END OF HEADER", "END OF HEADEX"), CorruptLogError, "no END OF"),
        (lambda t: t.replace("     3.04", "     4.01", 1), UnsupportedFormatError, "line 1"),
        (
            lambda t: t.replace("SYS / # / OBS TYPES", "SYS / # / OBS TYPEZ"),
            CorruptLogError,
            "types",
        ),
        (lambda t: t.replace("C1C D1C S1C", "L1C D1C S1C"), CorruptLogError, "pseudorange"),
    ],
)
def test_bad_headers_are_errors_naming_the_file_and_line(
    synth: Any, tmp_path: Path, edit: Any, error: type[Exception], where: str
) -> None:
    obs, nav = write_pair(tmp_path, synth)
    obs.write_text(edit(obs.read_text()))
    with pytest.raises(error, match=rf"drive.obs: .*{where}"):
        ingest([obs, nav], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_observations_without_navigation_are_an_error_that_says_so(
    synth: Any, tmp_path: Path
) -> None:
    obs, _ = write_pair(tmp_path, synth)
    with pytest.raises(IngestError, match="needs the RINEX navigation file"):
        ingest([obs], tmp_path / "out")


def test_navigation_without_gps_records_is_an_error_that_says_so(
    synth: Any, tmp_path: Path
) -> None:
    """A BeiDou-only navigation file (Hong Kong's .19b without its .19n) places no GPS
    satellite: refused, naming the file, what it holds and what to pass, not an empty table."""
    obs, nav = write_pair(tmp_path, synth)
    bds = tmp_path / "drive.19b"
    text = nav.read_text().replace("G: GPS   ", "C: BEIDOU")
    bds.write_text("\n".join("C" + ln[1:] if ln[:1] == "G" else ln for ln in text.splitlines()))
    n = len(synth.ephemeris)
    with pytest.raises(IngestError, match="no stream in the logs can fill") as err:
        ingest([obs, bds], tmp_path / "out")
    assert f"(drive.19b) hold no GPS ephemeris (BeiDou {n};" in str(err.value)
    assert "pass a GPS or mixed navigation file" in str(err.value)
    assert not (tmp_path / "out").exists()
    assert ingest([obs, bds, nav], tmp_path / "both").tables["gnss_obs"] > 0


def test_navigation_of_another_period_is_an_error_that_gives_both_periods(
    synth: Any, tmp_path: Path
) -> None:
    """Ephemerides two days after the observations serve no epoch: refused with both
    periods, not an empty table."""
    obs, _ = write_pair(tmp_path, synth)
    eph = synth.ephemeris
    later = 2 * 86_400 * NS_PER_S
    moved = Ephemeris(
        **{**eph._asdict(), "toe_ns": eph.toe_ns + later, "toc_ns": eph.toc_ns + later}
    )
    nav = tmp_path / "later.nav"
    rinex.write_nav(nav, moved)
    with pytest.raises(IngestError, match="no stream in the logs can fill") as err:
        ingest([obs, nav], tmp_path / "out")
    message = str(err.value)
    assert "the GPS ephemerides of the navigation files given are valid from" in message
    assert "pass the navigation file of the observations' period" in message
    first = str(calendar_from_gps(int(synth.tables["gnss_obs"]["t_ns"][0].as_py())))[:19]
    assert f"the observations run from {first}" in message
    assert not (tmp_path / "out").exists()


def test_a_truncated_navigation_record_is_dropped_and_reported(synth: Any, tmp_path: Path) -> None:
    obs, nav = write_pair(tmp_path, synth)
    lines = nav.read_text().splitlines(keepends=True)
    nav.write_text("".join(lines[:-3]))  # the last record loses 3 of its 8 lines
    start = len(lines) - 7
    result = ingest([obs, nav], tmp_path / "out")
    (defect,) = result.report["files"][1]["defects"]
    assert defect["kind"] == "truncated"
    assert defect["offset"] == start
    assert result.report["files"][1]["streams"][0]["count"] == len(synth.ephemeris) - 1
    with pytest.raises(CorruptLogError, match=rf"drive.nav: line {start}:"):
        ingest([obs, nav], tmp_path / "strict", options=IngestOptions(strict=True))


# ------------------------------------------------------------------- time (cases 35, 36)
def test_ten_bit_weeks_in_the_navigation_file_are_corrected(synth: Any, tmp_path: Path) -> None:
    obs, nav = write_pair(tmp_path / "good", synth)
    good = ingest([obs, nav], tmp_path / "good_out")
    eph = synth.ephemeris
    bad_nav = tmp_path / "bad" / "drive.nav"
    bad_nav.parent.mkdir()
    rinex.write_nav(bad_nav, eph)
    week = int(eph.week[0])
    bad_nav.write_text(
        bad_nav.read_text().replace(f"{float(week):.12E}", f"{float(week % 1024):.12E}")
    )
    shutil.copy(obs, tmp_path / "bad" / "drive.obs")
    bad = ingest([tmp_path / "bad" / "drive.obs", bad_nav], tmp_path / "bad_out")
    assert bad.report["files"][1]["counters"]["gps_week_rollover_records"] == len(eph)
    a = pq.read_table(tmp_path / "good_out" / "gnss_obs.parquet")
    b = pq.read_table(tmp_path / "bad_out" / "gnss_obs.parquet")
    assert a.equals(b)
    assert good.report["files"][1]["counters"] == {}


@pytest.mark.parametrize("stale", ["observation", "navigation"])
def test_a_file_one_1024_week_cycle_behind_the_other_is_moved_forward(
    synth: Any, tmp_path: Path, stale: str
) -> None:
    obs, nav = write_pair(tmp_path / "good", synth)
    ingest([obs, nav], tmp_path / "good_out")
    (tmp_path / "old").mkdir()
    back = -1024 * NS_PER_WEEK
    if stale == "observation":
        table = synth.tables["gnss_obs"]
        old = table.set_column(0, "t_ns", pa.array(table["t_ns"].to_numpy() + back))
        obs = tmp_path / "old" / "drive.obs"
        rinex.write_obs(obs, old, station(synth), interval_s=1.0)
    else:
        e = synth.ephemeris
        moved = type(e)(**{**e._asdict(), "toc_ns": e.toc_ns + back, "toe_ns": e.toe_ns + back})
        nav = tmp_path / "old" / "drive.nav"
        rinex.write_nav(nav, moved)
    result = ingest([obs, nav], tmp_path / "old_out")
    assert result.report["files"][0]["counters"][f"gps_week_rollover_{stale}_weeks"] == 1024
    assert any("rollover" in n for n in result.report["files"][0]["notes"])
    a = pq.read_table(tmp_path / "good_out" / "gnss_obs.parquet")
    b = pq.read_table(tmp_path / "old_out" / "gnss_obs.parquet")
    assert a.equals(b)


@pytest.mark.parametrize("packing", ["gzip", "hatanaka"])
def test_compressed_observations_give_the_same_table(
    synth: Any, tmp_path: Path, packing: str
) -> None:
    import gzip

    import hatanaka

    obs, nav = write_pair(tmp_path, synth)
    ingest([obs, nav], tmp_path / "plain")
    packed = tmp_path / ("drive.obs.gz" if packing == "gzip" else "drive.crx")
    data = obs.read_bytes()
    packed.write_bytes(gzip.compress(data) if packing == "gzip" else hatanaka.rnx2crx(data))
    ingest([packed, nav], tmp_path / "packed")
    a = pq.read_table(tmp_path / "plain" / "gnss_obs.parquet")
    b = pq.read_table(tmp_path / "packed" / "gnss_obs.parquet")
    assert a.equals(b)
