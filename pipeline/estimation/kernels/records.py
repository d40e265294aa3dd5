"""The records an INS replay kernel takes: its schedule, its settings and its run log.

They are ``typing.NamedTuple`` classes, which numba compiles as tuples with named fields, so
a kernel reads ``s.timeout_s`` instead of a packed vector at an index. The same records drive
the compiled kernels (``kernels.ekf``, ``kernels.ukf``, ``kernels.fwekf``) and the filterpy
reference backend (``estimation.reference``).

The run log's buffers are sized from the schedule before the run. A kernel never writes past
them: it counts what it could not write (``counts``), and ``RunLog.grown`` gives the log the
driver re-runs with, so that a run is complete or raises, never silently truncated.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import NamedTuple, TypeVar

import numpy as np

from navreplay.pipeline.estimation.models.ins import SpanWork
from navreplay.pipeline.nav.earth import F64, I64

log = logging.getLogger(__name__)
_T = TypeVar("_T")

CNT_OUT, CNT_INN, CNT_EV, CNT_STOP, CNT_T_FAIL = 0, 1, 2, 3, 4
CNT_DIM = 5
INN_I_COLS = 5  # t_ns, stream, sv, dim, accepted
INN_F_COLS = 8  # nis, gate, innovation[3], innovation sigma[3]
EV_I_COLS = 4  # t_ns, kind, stream, sv


class Schedule(NamedTuple):
    """What a segment replays: its start, the IMU samples and the stops.

    Attributes:
        t0: start time, ns; i0: first IMU sample after ``t0``; u0: IMU input at ``t0`` (6,).
        imu_t, imu: the IMU samples (see ``ins.propagate_span``).
        stops: the stop table (``models.measurement``: output, update and NHC epochs).
        obs_start: first row of each observation epoch (``models.measurement``).
        m_max: most measurement rows of one epoch.
    """

    t0: int
    i0: int
    u0: F64
    imu_t: I64
    imu: F64
    stops: I64
    obs_start: I64
    m_max: int


class Settings(NamedTuple):
    """An INS filter's settings (``InsFilterParams``, resolved for the dataset).

    Attributes:
        n: error-state dimension (15 loose, 17 tight).
        substeps: RK4 substeps per IMU interval; max_step_s: longest RK4 step, s.
        gap_s: an IMU interval longer than this is a gap (bridged with inflated noise), s.
        nhc_on: the non-holonomic constraint is applied.
        timeout_s: a stream rejected this long is reset (F2).
        reset_pos_sigma_m, reset_vel_sigma_mps, reset_clock_sigma_m: the least 1-sigma a
            reset leaves on position, velocity and receiver clock bias.
        max_pos_sigma_m, max_speed_mps: divergence limits.
        ukf_gamma: sigma-point spread sqrt(n + lambda); ukf_alpha, ukf_beta, ukf_kappa: the
            scaled unscented transform's parameters (UKF only; zero otherwise).
        noise: ``ins_errors.noise_vector``; lever_b: antenna lever arm, body, m (3,).
        nhc_sigma: NHC 1-sigma, lateral and vertical, m/s (2,).
        gate: chi-square threshold by block dimension, ``gate[d]`` (4,).
        wm, wc: the unscented weights (2n+1,) (UKF only; ones(1) otherwise).
    """

    n: int
    substeps: int
    max_step_s: float
    gap_s: float
    nhc_on: bool
    timeout_s: float
    reset_pos_sigma_m: float
    reset_vel_sigma_mps: float
    reset_clock_sigma_m: float
    max_pos_sigma_m: float
    max_speed_mps: float
    ukf_gamma: float
    ukf_alpha: float
    ukf_beta: float
    ukf_kappa: float
    noise: F64
    lever_b: F64
    nhc_sigma: F64
    gate: F64
    wm: F64
    wc: F64


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


class EpochBuffers(NamedTuple):
    """Scratch of the measurement epochs, allocated once per run (``common.epoch_buffers``).

    Attributes:
        rows, blocks: the epoch's row and block tables (``models.measurement``).
        z, r, nu: measurements, their variances and innovations (m_max,).
        H: Jacobian (m_max, n); S: innovation covariance (m_max, m_max).
        acc_rows: indices of the accepted rows.
        reject_since: per stream, when its current run of rejections began, ns (-1: none).
    """

    rows: I64
    blocks: I64
    z: F64
    r: F64
    nu: F64
    H: F64
    S: F64
    acc_rows: I64
    reject_since: I64


class SigmaWork(NamedTuple):
    """The UKF's workspace, allocated once per run (``kernels.ukf.sigma_work``).

    Attributes:
        sig: sigma points in filter coordinates (2n+1, n); sigX: as full states (2n+1, 18).
        L: Cholesky factor (n, n).
        prop: what ``ins.propagate_sigmas`` writes: the IMU input at the span's end, its
            scratch and the accumulated span terms (``ins.SpanWork``).
        Phi, Qd: the span's transition and process noise (n, n); sc: coordinate scale (n,).
        lanes, Y: ``ins.propagate_sigmas`` lanes and stage buffer.
    """

    sig: F64
    sigX: F64  # noqa: N815 (X: the full state, as everywhere in estimation)
    L: F64
    prop: SpanWork
    Phi: F64
    Qd: F64
    sc: F64
    lanes: I64
    Y: F64


class Fading(NamedTuple):
    """The fuzzy fading of ``fwekf`` (paper 004).

    Attributes:
        fz: ``FuzzyParams.vector()``; rules: ``fuzzy.RULES``.
        out_alpha: out, the fading factor in force at each output row.
    """

    fz: F64
    rules: I64
    out_alpha: F64


class Epoch(NamedTuple):
    """The measurement epoch an update processes (its rows and blocks in ``EpochBuffers``).

    Attributes:
        t_ns: its time, ns.
        m, nb: rows and blocks it uses (``measurement.epoch_layout``).
        w_ib_b: the angular rate at the epoch, body, rad/s (3,) (antenna lever-arm velocity).
    """

    t_ns: int
    m: int
    nb: int
    w_ib_b: F64


class UkfState(NamedTuple):
    """The UKF's estimate, updated in place.

    Attributes:
        s: the UKF coordinates (n,) (``models.ins``); P: their covariance (n, n).
        q_ref: the reference quaternion of the attitude coordinates (4,).
    """

    s: F64
    P: F64
    q_ref: F64


class RowPrediction(NamedTuple):
    """What predicts an epoch's rows from a full state besides the satellite table
    (``measurement.epoch_h``'s arguments).

    Attributes:
        rows: the row table (``models.measurement``); m: rows used.
        ref: the reference position (lat, lon, h) of the NED position rows (3,).
        w_ib_b: the angular rate, body, rad/s (3,); lever_b: antenna lever arm, body, m (3,).
    """

    rows: I64
    m: int
    ref: F64
    w_ib_b: F64
    lever_b: F64


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
