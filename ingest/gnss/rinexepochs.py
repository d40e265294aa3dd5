"""The epoch grammar of RINEX 2 and 3 observation bodies: one ``Epoch`` per observation epoch.

``epochs(head, lines, first_line, damage)`` walks the body line by line and yields, for
every complete epoch with flag 0 or 1, its line number, its calendar label and its satellite
records. A record is the satellite id and the record text without it, laid out so that
observation k occupies columns ``16k .. 16k + 13`` (value F14.3), ``16k + 14`` (loss of lock)
and ``16k + 15`` (signal strength) in both versions: RINEX 3 writes one line per satellite
after a 3-character id; RINEX 2 lists the satellites on the epoch line (12 per line, more on
continuation lines) and writes five observations per 80-column line, so its lines are padded
to 80 columns and joined.

Damage, recorded in the ``DamageLog`` with line numbers (E-RECOVER):

- an epoch cut by the end of the file, or a last line without its newline (an interrupted
  write), drops that epoch (``truncated``);
- an unreadable epoch line, or text where an epoch line is due, is skipped up to the next
  line that reads as an epoch line (``bad_data_skipped``);
- event epochs (flags 2-5: the satellite count is a count of header records that follow) and
  cycle-slip epochs (flag 6) are skipped and counted in ``counts``.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.gnss.rinextext import Header

_V2_EPOCH = re.compile(r"^ [ \d]\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d[ \d.]{11}  [0-6][ \d]{2}\d")
_V2_EVENT = re.compile(r"^ {28}[2-5][ \d]{2}\d")  # an event line may leave the date blank
_SV = re.compile(r"^[GRECJIS ][ \d]\d$")
_V2_OBS_PER_LINE = 5
_V2_SATS_PER_LINE = 12


@dataclass(frozen=True)
class Epoch:
    """One observation epoch.

    Attributes:
        line: line number of the epoch line.
        label: (year, month, day, hour, minute, seconds text) as written, on the file's
            time system.
        sats: (satellite id like ``G05``, record text, line number of the record).
    """

    line: int
    label: tuple[int, int, int, int, int, str]
    sats: list[tuple[str, str, int]]


@dataclass
class Counts:
    """What a pass over the body skipped."""

    events_skipped: int = 0
    defects: int = 0


def epochs(
    head: Header, lines: Iterator[str], damage: DamageLog, counts: Counts
) -> Iterator[Epoch]:
    """The epochs of the body that follows the header in ``lines``."""
    walker = _Walker(head, lines, damage, counts)
    return walker.v3() if head.version >= 3.0 else walker.v2()


class _Walker:
    def __init__(
        self, head: Header, lines: Iterator[str], damage: DamageLog, counts: Counts
    ) -> None:
        self.head = head
        self.lines = lines
        self.damage = damage
        self.counts = counts
        self.number = head.lines
        self.cut_line = 0  # line number of a last line without its newline
        self.reported_cut = False
        self.per_sat = -(-len(head.obs_types.get("G", [])) // _V2_OBS_PER_LINE)

    def next_line(self) -> str | None:
        """The next line without its end, or None at the end (or at a cut last line)."""
        raw = next(self.lines, None)
        if raw is None:
            return None
        self.number += 1
        if not raw.endswith("\n"):
            self.cut_line = self.number
            return None
        return raw.rstrip("\r\n")

    def finish(self) -> None:
        """A cut last line that no epoch reported is reported on its own."""
        if self.cut_line and not self.reported_cut:
            self.damage.record(
                Defect(
                    Completeness.TRUNCATED,
                    f"the last line ({self.cut_line}) is cut short: dropped",
                    offset=self.cut_line,
                )
            )

    def bad(self, number: int, what: str) -> None:
        self.counts.defects += 1
        self.damage.record(
            Defect(
                Completeness.BAD_DATA_SKIPPED, f"{what} at line {number}: skipped", offset=number
            )
        )

    def truncated(self, number: int, have: int, want: int) -> None:
        self.reported_cut = True
        self.damage.record(
            Defect(
                Completeness.TRUNCATED,
                f"the last epoch (line {number}) is cut by the end of the file: {have} of "
                f"{want} satellite records present, epoch dropped",
                offset=number,
            )
        )

    def skip(self, n: int) -> None:
        for _ in range(n):
            if self.next_line() is None:
                return

    # ----------------------------------------------------------------------------- RINEX 3
    def v3(self) -> Iterator[Epoch]:
        line = self.next_line()
        while line is not None:
            if not line.startswith(">"):
                if line.strip():
                    self.bad(self.number, "text outside any epoch")
                line = self.next_line()
                continue
            start = self.number
            try:
                flag, count = int(line[31:32]), int(line[32:35])
                if flag > 1:  # an event: its date may be blank; `count` records follow
                    self.counts.events_skipped += 1
                    self.skip(count)
                    line = self.next_line()
                    continue
                label = _label(line, ((2, 6), (7, 9), (10, 12), (13, 15), (16, 18)), (18, 29))
            except ValueError:
                self.bad(start, "unreadable epoch line")
                line = self.next_line()
                continue
            sats: list[tuple[str, str, int]] = []
            line = self.next_line()
            seen = 0
            while line is not None and seen < count and not line.startswith(">"):
                seen += 1
                if _SV.match(line[:3]):
                    sats.append((_sv(line[:3]), line[3:], self.number))
                else:
                    self.bad(self.number, f"unreadable satellite record {line[:12]!r}")
                line = self.next_line()
            if seen == count:
                yield Epoch(start, label, sats)
            elif line is None:
                self.truncated(start, seen, count)
            else:
                self.bad(start, f"epoch announcing {count} satellites with {len(sats)} records")
        self.finish()

    # ----------------------------------------------------------------------------- RINEX 2
    def v2(self) -> Iterator[Epoch]:
        line = self.next_line()
        while line is not None:
            if not (_V2_EPOCH.match(line) or _V2_EVENT.match(line)):
                if line.strip():
                    self.bad(self.number, "text where an epoch line is due")
                line = self._resync()
                continue
            start = self.number
            try:
                flag, count = int(line[28:29]), int(line[29:32])
                if flag > 1:  # an event: its date may be blank; `count` records follow
                    self.counts.events_skipped += 1
                    self.skip(count)
                    line = self.next_line()
                    continue
                label = _label(line, ((1, 3), (4, 6), (7, 9), (10, 12), (13, 15)), (15, 26))
            except ValueError:
                self.bad(start, "unreadable epoch line")
                line = self._resync()
                continue
            label = (label[0] + (2000 if label[0] < 80 else 1900), *label[1:])
            epoch = self._v2_body(start, line, count, label)
            if epoch is not None:
                yield epoch
            line = self.next_line()
        self.finish()

    def _v2_body(
        self, start: int, line: str, count: int, label: tuple[int, int, int, int, int, str]
    ) -> Epoch | None:
        ids = _v2_ids(line)
        while len(ids) < count:
            more = self.next_line()
            if more is None:
                self.truncated(start, 0, count)
                return None
            ids += _v2_ids(more)
        sats: list[tuple[str, str, int]] = []
        for sv in ids[:count]:
            parts: list[str] = []
            first = self.number + 1
            for _ in range(self.per_sat):
                obs = self.next_line()
                if obs is None:
                    self.truncated(start, len(sats), count)
                    return None
                parts.append(obs.ljust(80)[:80])
            sats.append((sv, "".join(parts), first))
        return Epoch(start, label, sats)

    def _resync(self) -> str | None:
        """Skip to the next line that reads as a RINEX 2 epoch line."""
        line = self.next_line()
        while line is not None and not (_V2_EPOCH.match(line) or _V2_EVENT.match(line)):
            line = self.next_line()
        return line


def _label(
    line: str, spans: tuple[tuple[int, int], ...], sec: tuple[int, int]
) -> tuple[int, int, int, int, int, str]:
    y, mo, d, h, mi = (int(line[a:b]) for a, b in spans)
    seconds = line[sec[0] : sec[1]]
    float(seconds)
    return y, mo, d, h, mi, seconds


def _sv(text: str) -> str:
    """``G05`` from ``G05``, ``G 5`` or `` 5`` (RINEX 2: a blank system letter is GPS)."""
    return (text[:1].strip() or "G") + text[1:3].replace(" ", "0")


def _v2_ids(line: str) -> list[str]:
    return [
        _sv(line[k : k + 3])
        for k in range(32, 32 + 3 * _V2_SATS_PER_LINE, 3)
        if line[k : k + 3].strip()
    ]
