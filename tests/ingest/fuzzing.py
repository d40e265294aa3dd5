"""The bad-input fuzzer's mutations and its verdict on one case (``test_fuzz_readers``).

A case damages one seed log (``fuzzseeds``) one way, ingests it in this process under a
per-case time limit, and classifies what happened:

- ``error``: a typed ``IngestError`` naming a file (the CLI's exit 2), nothing at the output;
- ``salvaged``: tables written, with each file's completeness in the report;
- anything else is a failure: an untyped exception (a traceback), a hang, an error naming
  no file, or anything left behind beside or at the output folder after an error.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import signal
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType

import numpy as np

from navreplay.ingest.api import ingest
from navreplay.ingest.errors import IngestError

#: a case is a hang after this much CPU time, s ...
TIME_LIMIT_S = 20.0
#: ... or this many times that of wall-clock time
WALL_FACTOR = 6.0
MUTATIONS = ("empty", "random", "truncate", "bitflip", "duplicate", "zero_block", "directory")


@dataclass(frozen=True)
class Case:
    """One fuzz case: the seed format, the mutation, and the seed of its random choices."""

    fmt: str
    mutation: str
    seed: int = 0

    @property
    def id(self) -> str:
        return f"{self.fmt}-{self.mutation}-{self.seed}"


def _truncate(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    cut = int(rng.integers(1, len(data)))
    return data[:cut], f"cut at byte {cut} of {len(data)}"


def _bitflip(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    buf = bytearray(data)
    bits = rng.choice(len(data) * 8, size=int(rng.integers(1, 9)), replace=False).tolist()
    for b in bits:
        buf[b // 8] ^= 1 << (b % 8)
    return bytes(buf), f"bits flipped in bytes {sorted(b // 8 for b in bits)}"


def _zero_block(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    size = int(rng.integers(16, 513))
    start = int(rng.integers(0, max(1, len(data) - size)))
    end = min(start + size, len(data))
    return data[:start] + bytes(end - start) + data[end:], f"bytes {start}..{end} zeroed"


_BYTES = {
    "empty": lambda data, rng: (b"", "0 bytes"),
    "random": lambda data, rng: (rng.bytes(len(data)), f"{len(data)} random bytes"),
    "truncate": _truncate,
    "bitflip": _bitflip,
    "duplicate": lambda data, rng: (data + data, f"the {len(data)} bytes twice"),
    "zero_block": _zero_block,
}


def mutate(path: Path, mutation: str, rng: np.random.Generator) -> str:
    """Damage ``path`` in place; returns what was done (offsets, sizes) for the verdict."""
    if mutation == "directory":
        path.unlink()
        path.mkdir()
        (path / "README").write_text("not a log\n")
        return "a directory in place of the file"
    data, what = _BYTES[mutation](path.read_bytes(), rng)
    path.write_bytes(data)
    return what


class Hang(BaseException):
    """Raised by the per-case alarm (a BaseException, so no reader's handler swallows it)."""


@contextlib.contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise ``Hang`` after ``seconds`` of this process's CPU time (a loop that never ends;
    on a loaded machine the wall clock runs several times faster than a case's work) or
    ``WALL_FACTOR`` times that of wall time (a wait that never ends)."""

    def _alarm(signum: int, frame: FrameType | None) -> None:
        clock = "CPU" if signum == signal.SIGPROF else "wall-clock"
        limit = seconds if signum == signal.SIGPROF else seconds * WALL_FACTOR
        raise Hang(f"no result after {limit} s of {clock} time")

    previous = {s: signal.signal(s, _alarm) for s in (signal.SIGPROF, signal.SIGALRM)}
    signal.setitimer(signal.ITIMER_PROF, seconds)
    signal.setitimer(signal.ITIMER_REAL, seconds * WALL_FACTOR)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.setitimer(signal.ITIMER_REAL, 0)
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@dataclass
class Verdict:
    case: Case
    outcome: str  # error | salvaged | failure
    detail: str
    completeness: tuple[str, ...] = ()


def leftovers(out: Path) -> list[str]:
    """Hidden temporaries beside ``out`` and anything at ``out`` (after an error)."""
    found = [p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]
    if out.exists():
        found.append(f"{out.name}/ exists")
    return found


def run_case(case: Case, seed_logs: tuple[Path, ...], target: Path, work: Path) -> Verdict:
    """Copy the seed into ``work``, damage it, ingest it, and judge (see the module doc)."""
    case_dir = work / case.id
    logs, victim = _copy(seed_logs, target, case_dir)
    what = mutate(victim, case.mutation, np.random.default_rng(case.seed))
    out_parent = case_dir / "out_parent"
    out_parent.mkdir()
    out = out_parent / "tables"
    logging.disable(logging.WARNING)
    try:
        with time_limit(TIME_LIMIT_S):
            result = ingest(list(logs), out)
    except IngestError as err:
        return _judge_error(case, what, err, out)
    except Hang as err:
        return Verdict(case, "failure", f"{what}: hang: {err}")
    except Exception as err:  # the fuzzer's point: any other exception is a traceback
        tb = "".join(traceback.format_exception(err)[-6:])
        return Verdict(case, "failure", f"{what}: traceback: {type(err).__name__}: {err}\n{tb}")
    finally:
        logging.disable(logging.NOTSET)
    beside = [p.name for p in out_parent.iterdir() if p.name != out.name]
    if beside:
        return Verdict(case, "failure", f"{what}: left beside the output: {beside}")
    flags = tuple(f for entry in result.report["files"] for f in entry["completeness"])
    return Verdict(case, "salvaged", f"{what}: {result.tables}", flags)


def _judge_error(case: Case, what: str, err: IngestError, out: Path) -> Verdict:
    left = leftovers(out)
    if err.path is None or str(err.path) not in str(err):
        return Verdict(case, "failure", f"{what}: the error names no file: {err}")
    if left:
        return Verdict(case, "failure", f"{what}: left behind after an error: {left}")
    return Verdict(case, "error", f"{what}: {type(err).__name__}: {err}")


def _copy(
    seed_logs: tuple[Path, ...], target: Path, case_dir: Path
) -> tuple[tuple[Path, ...], Path]:
    """The seed's logs copied under ``case_dir`` (directories whole), and the target's copy."""
    case_dir.mkdir(parents=True)
    logs: list[Path] = []
    victim: Path | None = None
    for p in seed_logs:
        dest = case_dir / p.name
        if p.is_dir():
            shutil.copytree(p, dest)
            if target.is_relative_to(p):
                victim = dest / target.relative_to(p)
        else:
            shutil.copy2(p, dest)
            if p == target:
                victim = dest
        logs.append(dest)
    assert victim is not None, f"{target} is not among {seed_logs}"
    return tuple(logs), victim
