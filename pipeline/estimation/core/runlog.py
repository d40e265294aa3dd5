"""The run log every compiled filter writes (estimates, innovations, events and their counters),
and the gated blocks of an epoch it records.

A kernel never writes past the log's buffers: it counts what it could not write (``counts``),
and ``RunLog.grown`` gives the log the driver re-runs with, so that a run is complete or raises,
never silently truncated.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import NamedTuple, TypeVar

import numpy as np

from navreplay.pipeline.nav.earth import F64, I64

log = logging.getLogger(__name__)


_T = TypeVar("_T")


CNT_OUT, CNT_INN, CNT_EV, CNT_STOP, CNT_T_FAIL = 0, 1, 2, 3, 4


CNT_DIM = 5


INN_I_COLS = 5  # t_ns, stream, sv, dim, accepted


INN_F_COLS = 8  # nis, gate, innovation[3], innovation sigma[3]


EV_I_COLS = 4  # t_ns, kind, stream, sv


class RunLog(NamedTuple):
    """What a kernel writes: outputs, innovations, events, and the counters ``CNT_*``.

    Attributes:
        out_t, out_x, out_P: output times, full states (K, 18) and error covariances (K, n, n).
        inn_i, inn_f: one row per gated block (``INN_I_COLS``, ``INN_F_COLS``).
        ev_i, ev_f: one row per event (``EV_I_COLS``) and its value.
        counts: rows written or wanted (``CNT_OUT``, ``CNT_INN``, ``CNT_EV``), stops done
            (``CNT_STOP``), time of a failure (``CNT_T_FAIL``).
    """

    out_t: I64
    out_x: F64
    out_P: F64  # noqa: N815 (P: the covariance, as everywhere in estimation)
    inn_i: I64
    inn_f: F64
    ev_i: I64
    ev_f: F64
    counts: I64

    @classmethod
    def allocate(cls, n_out: int, n_inn: int, n_ev: int, n: int, full_dim: int) -> RunLog:
        """Zeroed buffers for ``n_out`` outputs, ``n_inn`` innovations and ``n_ev`` events."""
        return cls(
            np.zeros(n_out, np.int64),
            np.zeros((n_out, full_dim)),
            np.zeros((n_out, n, n)),
            np.zeros((n_inn, INN_I_COLS), np.int64),
            np.zeros((n_inn, INN_F_COLS)),
            np.zeros((n_ev, EV_I_COLS), np.int64),
            np.zeros(n_ev),
            np.zeros(CNT_DIM, np.int64),
        )

    def capacity(self) -> tuple[int, int, int]:
        """(outputs, innovations, events) the buffers hold."""
        return self.out_t.shape[0], self.inn_i.shape[0], self.ev_i.shape[0]

    def wanted(self) -> tuple[int, int, int]:
        """(outputs, innovations, events) the run produced, written or not."""
        c = self.counts
        return int(c[CNT_OUT]), int(c[CNT_INN]), int(c[CNT_EV])

    def grown(self) -> RunLog | None:
        """A fresh log large enough for what this run wanted, or None if it all fitted."""
        have, want = self.capacity(), self.wanted()
        if all(w <= h for w, h in zip(want, have, strict=True)):
            return None
        n_out, n_inn, n_ev = (max(w, h) for w, h in zip(want, have, strict=True))
        n, full_dim = self.out_P.shape[1], self.out_x.shape[1]
        return RunLog.allocate(n_out, n_inn, n_ev, n, full_dim)

    def run_growing(self, run: Callable[[RunLog], _T]) -> tuple[_T, RunLog]:
        """``run(log)`` starting with this log, made again with a grown log until everything
        it wanted fitted; returns its last value and that log."""
        current = self
        while True:
            value = run(current)
            bigger = current.grown()
            if bigger is None:
                return value, current
            log.info("run log full (%s wanted, %s held): growing it", current.wanted(),
                     current.capacity())  # fmt: skip
            current = bigger


class GatedBlocks(NamedTuple):
    """An epoch's innovations and the gating of its blocks (``common.gate_blocks``).

    Attributes:
        nu: innovations (m,); S: the covariance they were gated against (m, m).
        blocks: the block table (``models.measurement``); nb: blocks used.
        nis: NIS per block (nb,); accepted: 1 if the block passed its gate (nb,).
    """

    nu: F64
    S: F64
    blocks: I64
    nb: int
    nis: F64
    accepted: I64
