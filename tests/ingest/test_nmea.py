"""NMEA 0183: logs written with pynmeagps (an independent NMEA implementation) round-trip onto
GPS time, text faults (catalogue cases 18, 19, 21, 29-33) are counted with line numbers, and the
real u-blox F9K drive and its NovAtel SPAN reference (../shared/data) give their SOURCE.txt
figures: 1,653 GNGGA (RTK fixed 967, float 632, DGPS 54) and 1,748 SPAN GGA."""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pymap3d
import pytest
from pynmeagps import GET, NMEAMessage, NMEAReader

from navreplay.ingest.api import IngestOptions, IngestResult, ingest, inspect
from navreplay.ingest.config import parse_dataset_config
from navreplay.ingest.detect import Format, detect
from navreplay.ingest.errors import ConfigError, CorruptLogError
from navreplay.ingest.gpstime import GPS_EPOCH_UNIX_NS, NS_PER_S
from navreplay.ingest.schema import FixType

DRIVE = (
    Path(__file__).resolve().parents[3] / "shared" / "data" / "gps_measurement_tools"
) / "nmea_f9k_vs_span_2020"
F9K = DRIVE / "MTV.Local1.ublox-F9K.20200206-181434.nmea"
SPAN = DRIVE / "MTV.Local1.SPAN.20200206-181434.gga"

START = dt.datetime(2020, 2, 7, 23, 59, 50)
LAT0, LON0 = 37.4263937, -122.0936525
QUALITIES = [4, 5, 4, 2, 1, 0, 6, 4, 4, 4, 5, 4, 4, 4, 4, 4, 4, 4, 4, 4]
FIX = {
    0: FixType.NO_FIX,
    1: FixType.FIX_3D,
    2: FixType.DGPS,
    4: FixType.RTK_FIXED,
    5: FixType.RTK_FLOAT,
    6: FixType.NO_FIX,
}


def _gps_ns(utc: dt.datetime) -> int:
    unix_ns = round(utc.replace(tzinfo=dt.UTC).timestamp() * NS_PER_S)
    return unix_ns - GPS_EPOCH_UNIX_NS + 18 * NS_PER_S  # GPS - UTC = 18 s since 2017


def _position(k: int) -> tuple[float, float]:
    lat, lon, _ = pymap3d.ned2geodetic(7.0 * k, 7.0 * k, 0.0, LAT0, LON0, 0.0)
    return float(lat), float(lon)


def epoch_sentences(k: int, *, rmc: bool = True, talker: str = "GN") -> list[bytes]:
    """One u-blox-like output cycle at START + k s, moving north-east at 9.9 m/s."""
    when = START + dt.timedelta(seconds=k)
    lat, lon = _position(k)
    where = {"lat": lat, "NS": "N", "lon": lon, "EW": "W"}
    speed_kn = math.hypot(7.0, 7.0) / (1852.0 / 3600.0)
    out = []
    if rmc:
        out.append(
            NMEAMessage(
                talker,
                "RMC",
                GET,
                time=when.time(),
                status="A",
                **where,
                spd=speed_kn,
                cog=45.0,
                date=when.date(),
                posMode="R",
            )
        )
    out.append(
        NMEAMessage(
            talker,
            "VTG",
            GET,
            cogt=45.0,
            cogtUnit="T",
            sogn=speed_kn,
            sognUnit="N",
            sogk=speed_kn * 1.852,
            sogkUnit="K",
            posMode="R",
        )
    )
    out.append(
        NMEAMessage(
            talker,
            "GGA",
            GET,
            time=when.time(),
            **where,
            quality=QUALITIES[k % len(QUALITIES)],
            numSV=12,
            HDOP=0.7,
            alt=4.4,
            altUnit="M",
            sep=-30.0,
            sepUnit="M",
            diffAge=1.0,
            diffStation=2000,
        )
    )
    # one GSA per constellation (NMEA 4.10 systemId): GPS, then GLONASS
    for system_id, svids in ((1, [2, 6, 12, 17, 19, 24, 28]), (2, [73, 80, 83])):
        used = {f"svid_{i + 1:02d}": s for i, s in enumerate(svids)}
        out.append(
            NMEAMessage(
                talker,
                "GSA",
                GET,
                opMode="A",
                navMode=3,
                **used,
                PDOP=1.5,
                HDOP=0.7,
                VDOP=1.3,
                systemId=system_id,
            )
        )
    view = {}
    for i, (sv, el, az, cno) in enumerate([(2, 25, 181, 42), (6, 45, 146, 45), (9, 5, 20, 0)]):
        view.update(
            {
                f"svid_{i + 1:02d}": sv,
                f"elv_{i + 1:02d}": el,
                f"az_{i + 1:02d}": az,
                f"cno_{i + 1:02d}": cno,
            }
        )
    out.append(NMEAMessage("GP", "GSV", GET, numMsg=1, msgNum=1, numSV=3, **view, signalID=1))
    out.append(
        NMEAMessage(
            talker,
            "GST",
            GET,
            time=when.time(),
            rangeRms=1.0,
            stdMajor=0.05,
            stdMinor=0.03,
            orient=10.0,
            stdLat=0.03,
            stdLong=0.04,
            stdAlt=0.05,
        )
    )
    return [m.serialize() for m in out]


def write_log(path: Path, epochs: int = 20, **kw: Any) -> list[bytes]:
    lines = [s for k in range(epochs) for s in epoch_sentences(k, **kw)]
    path.write_bytes(b"".join(lines))
    return lines


def _gnss(out: Path, table: str = "gnss") -> pd.DataFrame:
    return pd.read_parquet(out / f"{table}.parquet")


def test_nmea_is_detected_from_its_content(tmp_path: Path) -> None:
    write_log(tmp_path / "drive.log", 2)
    assert detect(tmp_path / "drive.log").format == Format.NMEA


def test_pynmeagps_log_round_trips_across_midnight(tmp_path: Path) -> None:
    write_log(tmp_path / "drive.nmea")
    result = ingest([tmp_path / "drive.nmea"], tmp_path / "out")
    assert result.tables == {"gnss": 20}
    assert result.report["time_base"]["base"] == "gps"
    g = _gnss(tmp_path / "out")
    expected_t = [_gps_ns(START + dt.timedelta(seconds=k)) for k in range(20)]
    np.testing.assert_array_equal(g["t_ns"], expected_t)  # 23:59:50 .. 00:00:09 next day
    lat, lon = zip(*(_position(k) for k in range(20)), strict=True)
    np.testing.assert_allclose(g["lat_deg"], lat, atol=2e-7)  # 1e-5 arc minutes written
    np.testing.assert_allclose(g["lon_deg"], lon, atol=2e-7)
    np.testing.assert_allclose(g["alt_m"], 4.4 - 30.0)  # MSL + geoid separation
    np.testing.assert_allclose(g["vel_n_mps"], 7.0, atol=1e-3)
    np.testing.assert_allclose(g["vel_e_mps"], 7.0, atol=1e-3)
    assert g["vel_d_mps"].isna().all()
    assert list(g["fix_type"]) == [FIX[q] for q in QUALITIES]
    assert (g["num_sats"] == 10).all()  # 7 GPS + 3 GLONASS from GSA, not GGA's 12
    assert (g["sats_in_view"] == 3).all()
    np.testing.assert_allclose(g[["pdop", "hdop", "vdop"]].iloc[0], [1.5, 0.7, 1.3])
    np.testing.assert_allclose(g["h_acc_m"], math.sqrt((0.03**2 + 0.04**2) / 2))
    np.testing.assert_allclose(g["v_acc_m"], 0.05)
    counters = result.report["tables"]["gnss"]["counters"]
    assert counters == {"quality_6_not_a_gnss_fix": 1}
    (f,) = result.report["files"]
    assert f["completeness"] == ["complete"]
    assert f["counters"]["sentences_GGA"] == 20


def test_the_date_is_carried_over_midnight_and_back_to_earlier_epochs(tmp_path: Path) -> None:
    path = tmp_path / "drive.nmea"
    lines = write_log(path, rmc=False)
    # One RMC only, in the 5th epoch: earlier epochs take its date, later ones advance it.
    rmc = epoch_sentences(4)[0]
    at = lines.index(epoch_sentences(4, rmc=False)[0])
    path.write_bytes(b"".join([*lines[:at], rmc, *lines[at:]]))
    ingest([path], tmp_path / "out")
    expected = [_gps_ns(START + dt.timedelta(seconds=k)) for k in range(20)]
    np.testing.assert_array_equal(_gnss(tmp_path / "out")["t_ns"], expected)


def test_without_any_date_the_time_of_day_is_kept_or_the_descriptor_dates_it(
    tmp_path: Path,
) -> None:
    path = tmp_path / "drive.nmea"
    write_log(path, rmc=False)
    result = ingest([path], tmp_path / "tod")
    assert result.report["time_base"]["base"] == "recorder"
    t = _gnss(tmp_path / "tod")["t_ns"].to_numpy()
    assert t[0] == (23 * 3600 + 59 * 60 + 50) * NS_PER_S
    assert t[-1] == (86_400 + 9) * NS_PER_S  # past midnight: the next day
    cfg = parse_dataset_config({"id": "d", "utc_date": "2020-02-07"})
    ingest([path], tmp_path / "dated", config=cfg)
    expected = [_gps_ns(START + dt.timedelta(seconds=k)) for k in range(20)]
    np.testing.assert_array_equal(_gnss(tmp_path / "dated")["t_ns"], expected)
    with pytest.raises(ConfigError, match="utc_date"):
        parse_dataset_config({"id": "d", "utc_date": "7.2.2020"})


def test_text_faults_are_counted_with_line_numbers(tmp_path: Path) -> None:
    lines = write_log(tmp_path / "clean.nmea")
    per = len(epoch_sentences(0))
    bad = list(lines)
    bad[2 * per + 2] = bad[2 * per + 2].replace(b",4,12,", b",4,13,")  # checksum now wrong
    bad[5 * per + 4] = bad[5 * per + 4][:20] + b"\r\n"  # cut: no checksum
    bad.insert(8 * per, b"#### receiver reboot ####\r\n")  # case 19: not a sentence
    bad[9 * per + 3] = bad[9 * per + 3].replace(b"4.4,M", b"nan,M")  # shifted, checksum wrong
    path = tmp_path / "bad.nmea"
    path.write_bytes(b"".join(bad)[:-6])  # case 18: the last line loses its end
    result = ingest([path], tmp_path / "out")
    (f,) = result.report["files"]
    assert f["completeness"] == ["bad_data_skipped", "checksum_mismatch", "partial_record_dropped"]
    defects = {d["kind"]: d for d in f["defects"]}
    assert defects["checksum_mismatch"]["reason"].startswith("2 sentences")
    assert defects["checksum_mismatch"]["offset"] == 2 * per + 3  # 1-based line number
    assert f"lines {2 * per + 3}, {9 * per + 4}" in defects["checksum_mismatch"]["reason"]
    assert f"lines {5 * per + 5}, {8 * per + 1})" in defects["bad_data_skipped"]["reason"]
    assert defects["partial_record_dropped"]["offset"] == len(bad)
    assert result.tables == {"gnss": 20 - 2}  # the two epochs that lost their GGA
    with pytest.raises(CorruptLogError, match=f"line {2 * per + 3}"):
        ingest([path], tmp_path / "strict", options=IngestOptions(strict=True))
    assert not (tmp_path / "strict").exists()


def test_nan_fields_and_time_faults_reach_the_hygiene(tmp_path: Path) -> None:
    epochs = [epoch_sentences(k) for k in range(60)]
    epochs[10], epochs[11] = epochs[11], epochs[10]  # case 29: a late epoch, not a new day
    epochs.insert(20, epochs[19])  # case 30: a cycle repeated (merges into its epoch)
    epochs.insert(26, epochs[24])  # case 30: a cycle repeated later (re-sorted, dropped)
    del epochs[41:47]  # case 33: a 7 s hole (6 cycles missing)
    gga = NMEAMessage(
        "GN",
        "GGA",
        GET,
        time=(START + dt.timedelta(seconds=29)).time(),
        lat="",
        NS="",
        lon="",
        EW="",
        quality=0,
        numSV=0,
        HDOP=99.9,
    )
    epochs[31] = [gga.serialize()]  # case 21/27: the cycle of k = 29 without a fix
    path = tmp_path / "faults.nmea"
    path.write_bytes(b"".join(s for e in epochs for s in e))
    result = ingest([path], tmp_path / "out")
    gnss = result.report["tables"]["gnss"]
    assert gnss["hygiene"]["reordered"] == 2
    assert gnss["hygiene"]["duplicates_exact_dropped"] == 1
    assert result.report["files"][0]["counters"]["gga_repeated_within_an_epoch"] == 1
    assert gnss["stats"]["gaps"]["count"] == 1
    assert gnss["stats"]["gaps"]["longest_s"] == 7.0
    g = _gnss(tmp_path / "out")
    empty = g[g["lat_deg"].isna()]
    assert len(empty) == 1
    assert empty[["lon_deg", "alt_m"]].isna().all().all()
    assert empty["fix_type"].iloc[0] == FixType.NO_FIX
    assert gnss["stats"]["nonfinite"]["lat_deg"] == {"nan": 1, "inf": 0}


def test_a_reference_receiver_fills_truth_when_the_descriptor_says_so(tmp_path: Path) -> None:
    write_log(tmp_path / "rover.nmea")
    write_log(tmp_path / "reference.gga", talker="GP")
    cfg = parse_dataset_config({"id": "d", "truth": {"topic": "GPGGA"}})
    (rover, _ref), plans = inspect(
        [tmp_path / "rover.nmea", tmp_path / "reference.gga"], config=cfg
    )
    assert {p.value: q.key for p, q in plans.items()} == {"gnss": "GNGGA", "truth": "GPGGA"}
    result = ingest(
        [tmp_path / "rover.nmea", tmp_path / "reference.gga"], tmp_path / "out", config=cfg
    )
    assert result.tables == {"gnss": 20, "truth": 20}
    truth = _gnss(tmp_path / "out", "truth")
    np.testing.assert_allclose(truth["vel_n_mps"], 7.0, atol=1e-3)
    assert truth[["vel_d_mps", "roll_rad", "yaw_rad"]].isna().all().all()
    assert "fix_type" not in truth
    gsv = rover.stream("GSV")
    assert gsv is not None
    assert gsv.table is None
    assert "gnss_obs" in gsv.detail


# ---------------------------------------------------------------------------------- real drive
@pytest.fixture(scope="module")
def real(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[IngestResult, pd.DataFrame, pd.DataFrame]:
    if not DRIVE.is_dir():
        pytest.skip(f"shared data not present at {DRIVE}")
    out = tmp_path_factory.mktemp("mtv") / "tables"
    cfg = parse_dataset_config({"id": "mtv", "utc_date": "2020-02-07", "truth": {"topic": "GPGGA"}})
    result = ingest([F9K, SPAN], out, config=cfg)
    return result, _gnss(out), _gnss(out, "truth")


def test_real_f9k_fixes_counts_qualities_and_checksums(
    real: tuple[IngestResult, pd.DataFrame, pd.DataFrame],
) -> None:
    result, gnss, _ = real
    assert result.tables == {"gnss": 1_653, "truth": 1_748}
    assert gnss["fix_type"].value_counts().to_dict() == {
        FixType.RTK_FIXED: 967,
        FixType.RTK_FLOAT: 632,
        FixType.DGPS: 54,
    }
    f9k, span = result.report["files"]
    (defect,) = f9k["defects"]
    assert defect["kind"] == "checksum_mismatch"
    assert defect["reason"].startswith("13 sentences with a wrong checksum skipped (lines 7181, ")
    assert f9k["counters"]["sentences_GGA"] == 1_653
    # Every SPAN RMC fails its checksum (its text was edited after checksumming): skipped, so
    # the reference has no velocity and its date comes from the descriptor.
    (span_defect,) = span["defects"]
    assert span_defect["reason"].startswith("1748 sentences with a wrong checksum")
    assert gnss["t_ns"].iloc[0] == _gps_ns(dt.datetime(2020, 2, 7, 2, 14, 17))
    stats = result.report["tables"]["gnss"]["stats"]
    assert stats["rate_hz"] == pytest.approx(1.0)
    assert stats["gaps"]["count"] == 4  # gaps of 6, 10, 19 and 40 s in the F9K log
    assert gnss["num_sats"].between(21, 25).all()
    assert gnss["sats_in_view"].between(30, 45).all()
    assert gnss["alt_m"].between(-35.0, 10.0).all()
    speed = np.hypot(gnss["vel_n_mps"], gnss["vel_e_mps"])
    assert speed.max() == pytest.approx(17.0, abs=1.0)  # SOURCE: max 17 m/s


def test_real_rtk_fixes_agree_with_the_span_reference(
    real: tuple[IngestResult, pd.DataFrame, pd.DataFrame],
) -> None:
    result, gnss, truth = real
    both = gnss.merge(truth, on="t_ns", suffixes=("", "_ref"))
    assert len(both) == 1_627
    n, e, d = pymap3d.geodetic2ned(
        both["lat_deg"],
        both["lon_deg"],
        both["alt_m"],
        both["lat_deg_ref"],
        both["lon_deg_ref"],
        both["alt_m_ref"],
    )
    horizontal = pd.Series(np.hypot(n, e)).groupby(both["fix_type"]).median()
    # RTK fixed: a constant ~0.5 m offset (the two antennas' lever arm), tight spread.
    assert horizontal[FixType.RTK_FIXED] == pytest.approx(0.48, abs=0.02)
    assert horizontal[FixType.RTK_FLOAT] == pytest.approx(0.50, abs=0.03)
    assert horizontal[FixType.DGPS] == pytest.approx(0.73, abs=0.05)
    fixed = (both["fix_type"] == FixType.RTK_FIXED).to_numpy()
    assert np.percentile(np.hypot(n, e)[fixed], 95) < 0.6
    assert np.median(np.abs(d[fixed])) < 0.1
    (align,) = result.report["time_base"]["alignment"]
    assert abs(align["lag_s"]) < 0.05
    assert align["correlation"] > 0.99
    assert align["speed_ratio"] == pytest.approx(1.0, abs=0.005)
    extent = pymap3d.geodetic2enu(
        truth["lat_deg"],
        truth["lon_deg"],
        0 * truth["alt_m"],
        truth["lat_deg"][0],
        truth["lon_deg"][0],
        0.0,
    )
    assert np.ptp(extent[0]) == pytest.approx(2_100, rel=0.05)  # SOURCE: ~2.1 km E-W
    assert np.ptp(extent[1]) == pytest.approx(1_200, rel=0.05)  # ~1.2 km N-S


def test_real_fixes_match_an_independent_nmea_parser(
    real: tuple[IngestResult, pd.DataFrame, pd.DataFrame],
) -> None:
    _, gnss, _ = real
    expected = []
    for raw in F9K.read_bytes().splitlines():
        if raw.startswith(b"$GNGGA"):
            msg = NMEAReader.parse(raw, validate=1)  # raises on a bad checksum
            expected.append((msg.lat, msg.lon, msg.alt + msg.sep, msg.quality))
    ref = np.array(expected, dtype=float)
    assert len(ref) == len(gnss)
    np.testing.assert_allclose(gnss[["lat_deg", "lon_deg", "alt_m"]], ref[:, :3], atol=1e-9)


def test_clock_steps_in_the_time_of_day_are_split_not_taken_for_midnight(tmp_path: Path) -> None:
    epochs = [epoch_sentences(k) for k in range(100)]
    later = [epoch_sentences(k + 3600) for k in range(30)]  # case 32: one hour forward
    back = [epoch_sentences(k - 5) for k in range(60, 100)]  # case 31: 5 s back, repeated
    path = tmp_path / "steps.nmea"
    path.write_bytes(b"".join(s for e in [*epochs[:60], *back, *later] for s in e))
    result = ingest([path], tmp_path / "out")
    gnss = result.report["tables"]["gnss"]
    (step,) = gnss["hygiene"]["clock_steps_backward"]
    assert step["step_s"] == pytest.approx(1.0 - 5.0)  # one cycle later, minus 5 s
    assert step["offset"] == 60 * len(epochs[0]) + 3  # the first GGA after the step
    (segment,) = gnss["stats"]["segments"]
    # The re-based run (55..94 s shifted by +5 s to 60..99 s) stays shifted: 3605 - 99 s.
    assert segment["jump_s"] == pytest.approx(3600.0 + 5.0 - 99.0)
    t = _gnss(tmp_path / "out")["t_ns"].to_numpy()
    assert (np.diff(t) > 0).all()
    assert t[-1] - t[0] < 86_400 * NS_PER_S  # no day was added
