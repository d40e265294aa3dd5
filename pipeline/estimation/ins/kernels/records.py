"""The records an INS replay kernel takes beside the run log (``core.runlog``): its
schedule, its settings, its work buffers and the epoch it updates on.

They are ``typing.NamedTuple`` classes, which numba compiles as tuples with named fields, so
a kernel reads ``s.timeout_s`` instead of a packed vector at an index. The same records drive
the compiled kernels (``kernels.ekf``, ``kernels.ukf``, ``kernels.fwekf``) and the filterpy
reference backend (``ins.reference``).
"""

from __future__ import annotations

from typing import NamedTuple

from navreplay.pipeline.estimation.ins.models.ins import SpanWork
from navreplay.pipeline.nav.earth import F64, I64


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
        nhc_on: the non-holonomic constraint is applied; still_on: the zero-velocity and
            zero-angular-rate updates at rest are (``models.standstill``).
        timeout_s: a stream rejected this long is reset (F2).
        return_gap_s, return_epochs: a stream back from a gap this long and rejected at this
            many epochs in a row is reset (``core.gating.returning_to_reset``).
        reset_pos_sigma_m, reset_vel_sigma_mps, reset_clock_sigma_m: the least 1-sigma a
            reset leaves on position, velocity and receiver clock bias.
        max_pos_sigma_m, max_speed_mps: divergence limits.
        ukf_gamma: sigma-point spread sqrt(n + lambda); ukf_alpha, ukf_beta, ukf_kappa: the
            scaled unscented transform's parameters (UKF only; zero otherwise).
        noise: ``ins_errors.noise_vector``; lever_b: antenna lever arm, body, m (3,).
        nhc_sigma: NHC 1-sigma, lateral and vertical, m/s (2,).
        still_sigma: ZUPT 1-sigma (m/s), the floor of the ZARU 1-sigma (rad/s) and the
            filter speed beyond which (plus 3 sigma) no standstill update applies (m/s) (3,).
        gate: chi-square threshold by block dimension, ``gate[d]`` (4,).
        wm, wc: the unscented weights (2n+1,) (UKF only; ones(1) otherwise).
    """

    n: int
    substeps: int
    max_step_s: float
    gap_s: float
    nhc_on: bool
    still_on: bool
    timeout_s: float
    return_gap_s: float
    return_epochs: int
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
    still_sigma: F64
    gate: F64
    wm: F64
    wc: F64


class EpochBuffers(NamedTuple):
    """Scratch of the measurement epochs, allocated once per run (``common.epoch_buffers``).

    Attributes:
        rows, blocks: the epoch's row and block tables (``models.measurement``).
        z, r, nu: measurements, their variances and innovations (m_max,).
        H: Jacobian (m_max, n); S: innovation covariance (m_max, m_max).
        acc_rows: indices of the accepted rows.
        reject_since: per stream, when its current run of rejections began, ns (-1: none).
        stream_clock: per stream (4, N_STREAMS): when it was last seen (ns; the run's start
            before its first measurement), its
            consecutive rejected epochs, whether that run began soon after a gap (1/0), and
            when it last came back from a gap (ns) (``core.gating.new_stream_clock``).
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
    stream_clock: I64


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
        still: the standstill rows' values (``measurement.STILL_COLS``).
        r_scale: multipliers of the fix rows' variances per kind (``measurement.K_PR``,):
            ones but in ``iae_ekf``, whose adaptive R they carry (``ins.iae``).
    """

    t_ns: int
    m: int
    nb: int
    w_ib_b: F64
    still: F64
    r_scale: F64


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


class SmoothLog(NamedTuple):
    """What the forward pass keeps for the backward (RTS) pass (``kernels.smoother``), one row
    per stop of the schedule and row 0 for the start; zero rows: no smoothing.

    The EKFs keep no covariance per stop: the prior of a stop is recomputed from the previous
    posterior and the transition (``ins_errors.transition`` of ``x`` and ``acc``), and the
    posterior of an output stop is the run log's. Only what cannot be recomputed goes to the
    ``pool``: the posterior of a stop that is not an output (an update epoch between output
    times), a prior the kernel changed beyond the transition (a stream reset, paper 004's
    fading), and the UKF's prior and sigma-point cross covariance at every stop.

    Attributes:
        x: the nominal state at the stop before its update, (S, 18).
        acc: the span accumulator that ended at the stop (``ins.SpanWork.acc``), (S, ACC_DIM).
        dx: the correction the update applied, error coordinates (S, n).
        rows: pool rows of the stop's posterior, prior and cross covariance (-1: not pooled)
            and its output row (-1: not an output), ``SM_*`` (S, 4).
        pool: covariances in error coordinates (M, n, n).
        counts: stops recorded (``SM_C_STOPS``) and pool rows wanted (``SM_C_POOL``), (2,).
    """

    x: F64
    acc: F64
    dx: F64
    rows: I64
    pool: F64
    counts: I64
