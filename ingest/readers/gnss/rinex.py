"""RINEX 2 and 3 observation and navigation files -> ``gnss_obs``.

An observation file becomes ``gnss_obs`` together with the navigation files given in the
same ingest (``navreplay ingest drive.obs drive.nav --out DIR``; ``ReadContext.siblings``):
its GPS L1 C/A pseudoranges, Doppler (``pseudorange_rate_mps = -lambda_L1 * D1C``) and
signal strength (``ingest.gnss.rinexobs``), with satellite positions, velocities and clocks
computed from the broadcast ephemerides (``ingest.gnss.rinexnav``, ``ingest.gnss.obsgeometry``). A
navigation file alone feeds no table; its inventory lists its records.

Rows dropped and why are counted in the table's ``counters``: ``no_ephemeris`` (no valid
record for that satellite and time), ``no_receiver_position``, ``rows_<system>_excluded``
(systems other than GPS: no orbit model here), ``events_skipped`` (epoch flags 2-6).
Navigation files that hold no GPS record (a BeiDou-only ``.yyb`` without its ``.yyn``) are
refused like missing ones, the error saying what they hold and what to pass; so are
navigation files none of whose GPS ephemerides is valid at any observation epoch (another
day's file), the error giving both periods.

GPS week rollover (catalogue case 35): observation epochs that lie a whole number of 1024-week
cycles before the navigation data (a receiver that wrote the 10-bit week) are moved forward
to the navigation data's cycle, and vice versa (the earlier one is the wrong one); the shift
is reported. Within a navigation file, a record's 10-bit week is corrected from its epoch
(``ingest.gnss.rinexnav``).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import IngestError
from navreplay.ingest.gnss.ephemeris import LAMBDA_L1_M, Ephemeris
from navreplay.ingest.gnss.obsgeometry import observation_geometry
from navreplay.ingest.gnss.rinexnav import NavData, Unreported, merge, read_nav
from navreplay.ingest.gnss.rinexobs import ObsRows, ObsScan, Signals, read_obs
from navreplay.ingest.gnss.rinextext import Header
from navreplay.ingest.gpstime import NS_PER_S, NS_PER_WEEK, calendar_from_gps
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
    selected_tables,
)
from navreplay.ingest.schema import TableName
from navreplay.ingest.timebase import TimeBase

log = logging.getLogger(__name__)

STREAM_KEY = "rinex:GPS L1 C/A"
_ROLLOVER_NS = 1024 * NS_PER_WEEK
_ROLLOVER_SLACK_NS = 8 * 86_400 * 10**9


class RinexReader(LogReader):
    """A RINEX observation file (with its navigation siblings), or a navigation file."""

    format = Format.RINEX

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self.variant = detected.variant
        self.is_nav = self.variant.split("+")[0] == "nav"
        self._nav: NavData | None = None
        self._nav_files = [
            d.path
            for d in ctx.siblings
            if d.format == Format.RINEX and d.variant.split("+")[0] == "nav"
        ]
        self._shift_ns = 0
        self._apart: str | None = None  # why the ephemerides serve no epoch (inventory)

    # ---------------------------------------------------------------------------- inventory
    def inventory(self) -> Inventory:
        if self.is_nav:
            return self._nav_inventory()
        head, sig, scan = self._scan()
        nav = self._load_nav()
        if nav is not None and not len(nav.ephemeris):
            table, detail = None, self._no_gps_ephemeris(nav)
        elif nav is not None:
            self._shift_ns = _rollover_shift(scan, nav)
            if self._shift_ns < 0:  # the navigation data are the stale ones: move them
                self._nav = nav = _shifted(nav, -self._shift_ns)
            table, detail = TableName.GNSS_OBS, f"{sig.pseudorange} {sig.doppler} {sig.strength}"
            self._apart = _apart(scan, nav, max(self._shift_ns, 0))
            if self._apart is not None:
                table, detail = None, self._apart
        else:
            table, detail = None, "needs the RINEX navigation file: pass it with the observations"
        others = {k: v for k, v in scan.rows_by_system.items() if k != "GPS"}
        if others:
            detail += "; no orbit model for " + ", ".join(f"{k} ({v})" for k, v in others.items())
        ahead = max(self._shift_ns, 0)
        stream = StreamInfo(
            key=STREAM_KEY,
            msgtype=f"RINEX {head.version:.2f} observations",
            count=scan.gps_rows,
            start_ns=None if scan.first_t_ns is None else scan.first_t_ns + ahead,
            end_ns=None if scan.last_t_ns is None else scan.last_t_ns + ahead,
            table=table,
            time_base=TimeBase.GPS,
            detail=detail,
        )
        notes = (f"{scan.epochs} epochs, time system {head.time_system}",)
        return Inventory(self.path, self.format, (stream,), notes)

    def _no_gps_ephemeris(self, nav: NavData) -> str:
        """Why the navigation files given cannot place the satellites (no GPS record)."""
        names = ", ".join(p.name for p in self._nav_files)
        records = ", ".join(f"{k} {v}" for k, v in sorted(nav.records.items())) or "no records"
        return (
            f"the navigation files given ({names}) hold no GPS ephemeris ({records}; only GPS "
            "has an orbit model here): pass a GPS or mixed navigation file of the same period"
        )

    def _nav_inventory(self) -> Inventory:
        nav = read_nav(self.path, self.variant, self.damage)
        eph = nav.ephemeris
        records = ", ".join(f"{k} {v}" for k, v in sorted(nav.records.items()))
        if nav.week_rollover_fixed:
            self.damage.note(
                f"GPS week rollover: {nav.week_rollover_fixed} records carried the 10-bit week; "
                "corrected from their epochs"
            )
            self.damage.count("gps_week_rollover_records", nav.week_rollover_fixed)
        if nav.week_inconsistent:
            self.damage.count("gps_week_inconsistent_records", nav.week_inconsistent)
        stream = StreamInfo(
            key="rinex:ephemeris",
            msgtype="RINEX navigation",
            count=len(eph),
            start_ns=int(eph.toc_ns.min()) if len(eph) else None,
            end_ns=int(eph.toc_ns.max()) if len(eph) else None,
            table=None,
            time_base=TimeBase.GPS,
            detail=f"records: {records or 'none'}; GPS ones used by the observation files",
        )
        return Inventory(self.path, self.format, (stream,))

    def _scan(self) -> tuple[Header, Signals, ObsScan]:
        # A counting pass; its defects are recorded by the reading pass, not here.
        head, sig, scan, chunks = read_obs(self.path, self.variant, Unreported(self.path))
        for _ in chunks:
            pass
        return head, sig, scan

    def _load_nav(self) -> NavData | None:
        if not self._nav_files:
            return None
        if self._nav is None:
            # each navigation file's own reader reports its defects
            navs = [
                read_nav(p, _variant(p, self.ctx.siblings), Unreported(p)) for p in self._nav_files
            ]
            self._nav = merge(navs)
        return self._nav

    # ---------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        if self.is_nav or STREAM_KEY not in selected_tables(selections):
            return
        nav = self._load_nav()
        if nav is None:
            raise IngestError(
                "RINEX observations without a navigation file",
                path=self.path,
                hint="pass the .nav/.yyn file of the same period in the same ingest",
            )
        if not len(nav.ephemeris):
            raise IngestError(self._no_gps_ephemeris(nav), path=self.path)
        if self._apart is not None:
            raise IngestError(self._apart, path=self.path)
        if self._shift_ns:
            weeks = abs(self._shift_ns) // NS_PER_WEEK
            which = "observation" if self._shift_ns > 0 else "navigation"
            self.damage.note(
                f"GPS week rollover: the {which} epochs were {weeks} weeks (1024-week cycles) "
                "behind the other file and were moved forward"
            )
            self.damage.count(f"gps_week_rollover_{which}_weeks", weeks)
        head, sig, scan, chunks = read_obs(self.path, self.variant, self.damage)
        for rows in chunks:
            yield self._batch(rows, head, sig, nav)
        for name, n in scan.rows_by_system.items():
            if name != "GPS":
                self.damage.count(f"rows_{name}_excluded", n)
        if scan.skipped.events_skipped:
            self.damage.count("events_skipped", scan.skipped.events_skipped)

    def _batch(self, rows: ObsRows, head: Header, sig: Signals, nav: NavData) -> Batch:
        has_pr = np.isfinite(rows.pseudorange_m)
        counters = {"no_pseudorange": int(np.count_nonzero(~has_pr))}
        t = rows.t_ns[has_pr] + max(self._shift_ns, 0)
        prn = rows.prn[has_pr]
        pr = rows.pseudorange_m[has_pr]
        geo = observation_geometry(
            nav.ephemeris, t, prn, pr, approx_ecef_m=_approx(head), klobuchar=nav.klobuchar
        )
        counters.update(geo.counters)
        keep = geo.keep
        if not keep.any():
            return Batch(
                STREAM_KEY, TableName.GNSS_OBS, _empty(), np.empty(0, np.int64), counters=counters
            )
        dop = rows.doppler_hz[has_pr][keep]
        cn0 = rows.strength[has_pr][keep]
        columns: dict[str, np.ndarray] = {
            "t_ns": t[keep],
            "sv": np.array([f"G{p:02d}" for p in prn[keep]]),
            "pseudorange_m": pr[keep],
            "pseudorange_rate_mps": -dop * LAMBDA_L1_M,
            "cn0_dbhz": cn0,
            **geo.columns,
        }
        nulls = {"pseudorange_rate_mps": np.isnan(dop), "cn0_dbhz": np.isnan(cn0)}
        info = {
            "signal": f"GPS L1 C/A: {sig.pseudorange}, {sig.doppler}, {sig.strength}",
            "time_system": head.time_system,
            "satellite_states": "GPS broadcast ephemeris (IS-GPS-200) at transmit time, "
            "receive-time ECEF frame",
            "iono_delay": "broadcast Klobuchar" if nav.klobuchar is not None else "not given",
        }
        return Batch(
            STREAM_KEY,
            TableName.GNSS_OBS,
            columns,
            rows.line[has_pr][keep],
            nulls=nulls,
            counters=counters,
            info=info,
        )


def _variant(path: Path, siblings: Sequence[Detected]) -> str:
    return next((d.variant for d in siblings if d.path == path), "nav")


def _approx(head: Header) -> np.ndarray | None:
    return None if head.approx_ecef_m is None else np.asarray(head.approx_ecef_m, np.float64)


def _rollover_shift(scan: ObsScan, nav: NavData) -> int:
    """Whole 1024-week cycles to add to the observation epochs (negative: the navigation data
    are the stale ones), or 0 when they already agree."""
    if scan.first_t_ns is None or not len(nav.ephemeris):
        return 0
    gap = float(np.median(nav.ephemeris.toc_ns)) - scan.first_t_ns
    cycles = round(gap / _ROLLOVER_NS)
    if cycles == 0 or abs(gap - cycles * _ROLLOVER_NS) > _ROLLOVER_SLACK_NS:
        return 0
    return int(cycles) * _ROLLOVER_NS


def _apart(scan: ObsScan, nav: NavData, ahead_ns: int) -> str | None:
    """Why no GPS ephemeris given can serve any observation epoch (none is valid within
    half its fit interval of them), or None when some can."""
    eph = nav.ephemeris
    if scan.first_t_ns is None or scan.last_t_ns is None or not len(eph):
        return None
    half = np.where(eph.fit_interval_h > 0, eph.fit_interval_h, 4.0) * 1800.0 * NS_PER_S
    lo, hi = eph.toe_ns - half.astype(np.int64), eph.toe_ns + half.astype(np.int64)
    first, last = scan.first_t_ns + ahead_ns, scan.last_t_ns + ahead_ns
    if np.any((lo <= last) & (hi >= first)):
        return None

    def when(t: int) -> str:
        return str(calendar_from_gps(int(t)))[:19]

    return (
        f"the GPS ephemerides of the navigation files given are valid from {when(lo.min())} "
        f"to {when(hi.max())} GPS time, the observations run from {when(first)} to "
        f"{when(last)}: pass the navigation file of the observations' period"
    )


def _shifted(nav: NavData, ns: int) -> NavData:
    e = nav.ephemeris
    eph = Ephemeris(**{**e._asdict(), "toc_ns": e.toc_ns + ns, "toe_ns": e.toe_ns + ns})
    return NavData(eph, nav.klobuchar, nav.leap_seconds, nav.records, nav.week_rollover_fixed)


def _empty() -> dict[str, np.ndarray]:
    return {"t_ns": np.empty(0, np.int64), "sv": np.empty(0, dtype="<U3")}
