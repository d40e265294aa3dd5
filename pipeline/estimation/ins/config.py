"""Typed parameters of the INS/GNSS filters: the ``filters.<name>`` sections of params.yaml.

Each filter name of architecture section 3 has one section, an ``InsFilterParams``. The name
fixes the estimator (``*_ekf*``: error-state EKF, ``*_ukf*``: total-state UKF), the coupling
(``lc_*``: GNSS fixes, ``tc_*``: pseudoranges and rates) and whether the non-holonomic
constraint is fused (``*_nhc``); ``FiltersParams`` checks that each section carries the
sub-sections its name needs (``ukf`` for UKFs, ``nhc`` for ``_nhc`` variants) and no others.

Sensor metadata from the dataset's ``meta.json`` wins over these values: ``sensors.imu_noise``
replaces ``imu_noise`` and ``sensors.lever_arm_m`` is the antenna lever arm (the params have no
lever arm; a dataset without one has the antenna at the IMU).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Literal

from navreplay.ingest.config import ImuNoise
from navreplay.ingest.typed import FieldError
from navreplay.pipeline.estimation.core.checks import positive
from navreplay.pipeline.estimation.core.integrity import IntegrityParams
from navreplay.pipeline.estimation.ins.fuzzy import FuzzyParams
from navreplay.pipeline.estimation.ins.iae import IaeParams

Estimator = Literal["ekf", "ukf"]
Coupling = Literal["loose", "tight"]


@dataclass(frozen=True)
class InitParams:
    """Initialization and coarse alignment.

    The filter starts at the first GNSS epoch where the horizontal speed reaches
    ``align_speed_mps`` and ``align_sigmas`` times its own 1-sigma, there and at the next
    ``align_epochs - 1`` epochs (motion, not noise: speed differenced from 1.5 m fixes a second
    apart is ~2 m/s of pure noise at standstill): heading from the GNSS velocity, roll and
    pitch from the specific force (corrected by the GNSS-derived acceleration), position and
    velocity from GNSS. A static period before it (``static_window_s`` of IMU with ``|f| - g``
    and ``|w|`` below the thresholds) initializes the gyro bias.

    Attributes:
        align_speed_mps: minimum horizontal GNSS speed for the heading alignment, m/s.
        align_sigmas: ... and minimum multiple of the speed's own 1-sigma (the receiver's
            speed accuracy, or the fixes' accuracy propagated through the difference).
        align_epochs: consecutive GNSS epochs that must pass both tests.
        static_window_s: shortest static window used for the gyro-bias estimate, s.
        static_accel_tol_mps2: static if the specific-force norm stays within this of g.
        static_gyro_tol_radps: static if the angular-rate norm stays below this (above any
            plausible gyro bias: a turn-on bias of 1 deg/s per axis is 0.03 rad/s).
        pos_sigma_m: initial position 1-sigma per axis (at least the fix accuracy), m.
        vel_sigma_mps: initial velocity 1-sigma per axis, m/s.
        roll_pitch_sigma_rad: initial roll and pitch 1-sigma, rad.
        yaw_sigma_rad: initial heading 1-sigma, rad.
        clock_bias_sigma_m: initial receiver clock bias 1-sigma (tight coupling), m.
        clock_drift_sigma_mps: initial receiver clock drift 1-sigma (tight coupling), m/s.
        motion_yaw_sigma_max_rad: a heading from motion (``heading``: a multirotor, or a
            vehicle whose course never gives one) starts the filter at the first epoch where
            its 1-sigma is this small, rad.
        tilt_tau_s: time constant of the tilt filter of the heading from motion, s (long:
            a multirotor's specific force leans with its acceleration).
        drift_horizon_s: the heading from motion may wander by the gyro bias sigma times this
            horizon per square-root second (a random walk covering the bias's drift), s.
        course_wait_s: a ground vehicle whose course start comes this long after its first
            confirmed motion (reversing slower than ``align_speed_mps``, creeping, noisy
            differenced fixes) starts from the heading from motion instead, where that is
            trusted by then, s.
    """

    align_speed_mps: float = 2.0
    align_sigmas: float = 5.0
    align_epochs: int = 3
    static_window_s: float = 2.0
    static_accel_tol_mps2: float = 0.6
    static_gyro_tol_radps: float = 0.05
    pos_sigma_m: float = 3.0
    vel_sigma_mps: float = 0.3
    roll_pitch_sigma_rad: float = 0.03
    yaw_sigma_rad: float = 0.1
    clock_bias_sigma_m: float = 10.0
    clock_drift_sigma_mps: float = 1.0
    motion_yaw_sigma_max_rad: float = 0.15
    tilt_tau_s: float = 20.0
    drift_horizon_s: float = 60.0
    course_wait_s: float = 3.0

    def __post_init__(self) -> None:
        positive(self, *(f.name for f in fields(self)))


@dataclass(frozen=True)
class GnssNoiseParams:
    """Measurement noise of the GNSS updates; reported accuracies are floored (F8).

    Attributes:
        pos_sigma_floor_m: floor on the receiver's h_acc / v_acc, m.
        pos_sigma_default_m: position 1-sigma when the receiver reports none, m.
        pos_error_corr_time_s: correlation time of the fixes' position errors (multipath,
            atmosphere), s, where it cannot be learned from the log (``learn_fix_noise``). A
            first-order Gauss-Markov error sampled every dt carries about the information of
            one independent fix per 2 tau, so the fix variance is inflated by
            ``(1 + phi) / (1 - phi)``, ``phi = exp(-dt/tau)`` (~``1 + 2 tau / dt``; 0: white
            errors, no inflation). Reported accuracies are per-fix sigmas and say nothing about
            correlation; without this a loosely coupled filter averages correlated errors as
            if they were white and becomes overconfident. The inflation applies to the update
            only: a fix is gated, and its NIS computed, against the marginal variance
            (``measurement.gate_shift``).
        learn_fix_noise: learn the fix errors' correlation time (and their size where the
            receiver reports no accuracy) from the log's fixes against its receiver velocity
            (``ins.fixnoise``); without a receiver velocity, or too few fixes, the configured
            values are used. ``metrics.json`` ``fix_noise`` says which, and why.
        fix_error_states: where the learned errors are correlated (tau of three fix intervals
            or more), carry the north and east fix errors as first-order Gauss-Markov states
            of the learned tau and size instead of inflating the fix variances (loose
            coupling; the vertical keeps the inflation): the filter then tells the slowly
            wandering fix error from the motion the IMU and the receiver velocity show.
        vel_sigma_floor_mps: floor on the receiver's speed accuracy, m/s.
        vel_sigma_default_mps: velocity 1-sigma when the receiver reports none, m/s.
        use_velocity: fuse the receiver velocity where present (loose coupling).
        use_fix_latency: apply each fix at its own epoch, ``t_ns - latency_s``, where the
            table has a ``latency_s`` column (arrival minus the receiver's epoch).
        pseudorange_sigma_floor_m: floor on the pseudorange 1-sigma, m.
        pseudorange_sigma_default_m: pseudorange 1-sigma when the table has none, m.
        pseudorange_rate_sigma_floor_mps: floor on the pseudorange-rate 1-sigma, m/s.
        pseudorange_rate_sigma_default_mps: pseudorange-rate 1-sigma when absent, m/s.
        elevation_mask_deg: satellites below this elevation are not used (tight coupling).
    """

    pos_sigma_floor_m: float = 0.5
    pos_sigma_default_m: float = 3.0
    pos_error_corr_time_s: float = 0.0
    learn_fix_noise: bool = True
    fix_error_states: bool = False
    vel_sigma_floor_mps: float = 0.05
    vel_sigma_default_mps: float = 0.2
    use_velocity: bool = True
    use_fix_latency: bool = True
    pseudorange_sigma_floor_m: float = 0.5
    pseudorange_sigma_default_m: float = 3.0
    pseudorange_rate_sigma_floor_mps: float = 0.02
    pseudorange_rate_sigma_default_mps: float = 0.1
    elevation_mask_deg: float = 10.0

    def __post_init__(self) -> None:
        positive(self, "pos_error_corr_time_s", allow_zero=True)
        positive(
            self,
            "pos_sigma_floor_m",
            "pos_sigma_default_m",
            "vel_sigma_floor_mps",
            "vel_sigma_default_mps",
            "pseudorange_sigma_floor_m",
            "pseudorange_sigma_default_m",
            "pseudorange_rate_sigma_floor_mps",
            "pseudorange_rate_sigma_default_mps",
        )
        if not -90.0 <= self.elevation_mask_deg < 90.0:
            raise FieldError("elevation_mask_deg", "must be within [-90, 90)")

    def white(self) -> GnssNoiseParams:
        """This model with the fix errors taken as white, as paper 004 takes them: no
        correlation configured or learned, no error states (the accuracies as they are)."""
        return replace(
            self, pos_error_corr_time_s=0.0, learn_fix_noise=False, fix_error_states=False
        )


@dataclass(frozen=True)
class ClockParams:
    """Receiver clock model (tight coupling): bias and drift as random walks (paper 001).

    The defaults are a typical TCXO (Allan coefficients h0 = 2e-19, h-2 = 2e-20:
    ``c^2 h0 / 2`` and ``2 pi^2 c^2 h-2``).

    Attributes:
        bias_psd_m2ps: white-noise density driving the clock bias, m^2/s.
        drift_psd_m2ps3: white-noise density driving the clock drift, m^2/s^3.
    """

    bias_psd_m2ps: float = 0.01
    drift_psd_m2ps3: float = 0.04

    def __post_init__(self) -> None:
        positive(self, "bias_psd_m2ps", "drift_psd_m2ps3", allow_zero=True)


@dataclass(frozen=True)
class GatingParams:
    """Chi-square innovation gating with a timeout reset.

    Each measurement block (a fix's position, its velocity, one satellite's pseudorange and
    rate, the NHC pair) is gated on its NIS against the chi-square quantile ``probability``
    for its dimension. When a stream has been rejected without interruption for longer than
    ``timeout_s``, the covariance of the states it observes is reset (inflated to at least the
    current innovation) and the epoch is processed again, so a persistent step is followed
    instead of locking the filter out (bad-inputs F2). A stream that comes back after a gap
    (an outage) and, within ``timeout_s`` of its return, is rejected at ``return_epochs``
    consecutive epochs is reset at once:
    after an outage the filter, not the returning measurements, is the one that drifted, and
    waiting out the timeout only lets the error grow (bad-inputs F4).

    Attributes:
        probability: gate probability, e.g. 0.9999.
        timeout_s: continuous rejection time that triggers a reset, s.
        return_gap_s: a stream silent this long (an outage) is returning when it comes back, s.
        return_epochs: consecutive rejected epochs of a returning stream that reset it.
        reset_pos_sigma_m: minimum position 1-sigma after a reset, m.
        reset_vel_sigma_mps: minimum velocity 1-sigma after a reset, m/s.
        reset_clock_sigma_m: minimum clock-bias 1-sigma after a reset, m.
    """

    probability: float = 0.9999
    timeout_s: float = 5.0
    return_gap_s: float = 5.0
    return_epochs: int = 2
    reset_pos_sigma_m: float = 10.0
    reset_vel_sigma_mps: float = 1.0
    reset_clock_sigma_m: float = 30.0

    def __post_init__(self) -> None:
        if not 0.5 < self.probability < 1.0:
            raise FieldError("probability", "must be within (0.5, 1)")
        positive(self, "timeout_s", "reset_pos_sigma_m", "reset_vel_sigma_mps")
        positive(self, "reset_clock_sigma_m", "return_gap_s", "return_epochs")


@dataclass(frozen=True)
class StepParams:
    """Time stepping of the replay loop.

    The loop stops on a grid of ``step_s`` (the covariance / sigma-point step and the output
    rate) and at every update epoch. Between stops the navigation state (and every UKF sigma
    point) is integrated through the IMU samples by RK4 with ``substeps`` steps per sample
    interval, more where an interval exceeds ``max_rk4_step_s``. IMU intervals longer than
    ``imu_gap_s`` are gaps: bridged by interpolating the samples on both sides, with white
    process noise of densities ``gap_*_psd`` added for the unknown manoeuvres (a 2 s gap adds
    sqrt(2 q) to the velocity sigma); longer than ``imu_gap_max_s`` they end a segment and
    the filter re-aligns after them. A tumble ends a segment too: samples turning faster than
    ``tumble_rate_radps`` and more than ``tumble_rotation_rad`` from one sample to the next
    (a crash or a flip logged at tens of Hz, which no integration of the samples follows);
    the next segment starts ``tumble_settle_s`` after the last of them.

    Attributes:
        step_s: covariance propagation, sigma-point redraw and output interval, s.
        substeps: RK4 steps per IMU interval (paper 001: 10).
        max_rk4_step_s: longest single RK4 step, s.
        imu_gap_s: an IMU interval longer than this is a gap, s.
        imu_gap_max_s: a gap longer than this splits the run into segments, s.
        gap_accel_psd_m2ps3: white acceleration noise density during a gap, m^2/s^3.
        gap_gyro_psd_rad2ps: white angular-rate noise density during a gap, rad^2/s.
        tumble_rate_radps, tumble_rotation_rad, tumble_settle_s: a tumble, see above.
        second_order_corr_s: correlation time given the term the linearised velocity error
            leaves out, the attitude error times the accelerometer-bias error
            (``ins_errors.second_order_noise``), s; 0 leaves it out.
    """

    step_s: float = 0.1
    substeps: int = 1
    max_rk4_step_s: float = 0.02
    imu_gap_s: float = 0.05
    imu_gap_max_s: float = 5.0
    gap_accel_psd_m2ps3: float = 4.0
    gap_gyro_psd_rad2ps: float = 0.05
    tumble_rate_radps: float = 10.0
    tumble_rotation_rad: float = 0.2
    tumble_settle_s: float = 1.0
    second_order_corr_s: float = 0.0

    def __post_init__(self) -> None:
        positive(self, "step_s", "max_rk4_step_s", "imu_gap_s", "imu_gap_max_s")
        positive(self, "second_order_corr_s", allow_zero=True)
        positive(self, "tumble_rate_radps", "tumble_rotation_rad", "tumble_settle_s")
        positive(self, "gap_accel_psd_m2ps3", "gap_gyro_psd_rad2ps", allow_zero=True)
        if not 1 <= self.substeps <= 100:
            raise FieldError("substeps", "must be within 1..100")
        if self.imu_gap_max_s < self.imu_gap_s:
            raise FieldError("imu_gap_max_s", "must be >= imu_gap_s")


@dataclass(frozen=True)
class DivergenceParams:
    """The NaN barrier and divergence limits.

    A non-finite state or covariance, a covariance that stays indefinite after repair, or a
    position 1-sigma above ``max_pos_sigma_m`` ends the run: ``on_divergence: raise`` raises
    ``DivergenceError``; ``flag`` keeps the output up to that time and marks the run diverged
    in metrics.json.

    Attributes:
        on_divergence: ``raise`` or ``flag``.
        max_pos_sigma_m: largest acceptable horizontal position 1-sigma, m.
        max_speed_mps: largest physically plausible speed, m/s.
    """

    on_divergence: Literal["raise", "flag"] = "raise"
    max_pos_sigma_m: float = 1.0e5
    max_speed_mps: float = 200.0

    def __post_init__(self) -> None:
        positive(self, "max_pos_sigma_m", "max_speed_mps")


@dataclass(frozen=True)
class NhcParams:
    """Non-holonomic constraint: body-frame v_y = 0 and v_z = 0 as pseudo-measurements.

    Fused at every GNSS epoch together with GNSS, and on its own between epochs at
    ``rate_hz`` (paper 001: applied together with GNSS, not only during outages).

    Attributes:
        sigma_lateral_mps: 1-sigma of the lateral constraint v_y^b = 0, m/s.
        sigma_vertical_mps: 1-sigma of the vertical constraint v_z^b = 0, m/s.
        rate_hz: rate of the pseudo-measurements, Hz.
    """

    sigma_lateral_mps: float = 0.1
    sigma_vertical_mps: float = 0.1
    rate_hz: float = 10.0

    def __post_init__(self) -> None:
        positive(self, "sigma_lateral_mps", "sigma_vertical_mps", "rate_hz")


@dataclass(frozen=True)
class StandstillParams:
    """Standstill detection and the zero-velocity / zero-angular-rate updates at rest
    (``ins.standstill``, ``models.standstill``), for every INS filter.

    Attributes:
        enabled: detect standstill and fuse ZUPT and ZARU while it lasts.
        window_s: the IMU window whose spread is tested, centred on each sample, s.
        noise_factor: at rest while the spread (RMS about the window's mean) of the specific
            force and of the angular rate stays below this many times the IMU's own sample
            noise (the dataset's noise model, or the one measured in the log).
        max_rate_radps: the mean angular rate of a window at rest stays below this: above
            any plausible gyro bias (a turn-on bias of 1 deg/s on every axis is 1.7 deg/s),
            below a turn; a slower turn in place is left to the ZARU's gate.
        gnss_speed_mps: a GNSS velocity (or, without one, the displacement of the fixes over
            ``gnss_baseline_s``) faster than this and 3 sigma of its own noise vetoes rest.
        gnss_baseline_s: the least time between the fixes differenced without a velocity, s.
        vel_sigma_mps: 1-sigma of the zero-velocity pseudo-measurement.
        rate_sigma_radps: floor of the zero-angular-rate 1-sigma (vibration, quantization),
            added to the gyro noise averaged over the update interval.
        max_speed_mps: no update while the filter's own speed exceeds this plus 3 sigma of
            it: a vehicle cruising at constant speed without vibration (a simulator) passes
            the IMU's tests.
    """

    enabled: bool = True
    window_s: float = 1.0
    noise_factor: float = 3.0
    max_rate_radps: float = 0.05
    gnss_speed_mps: float = 0.5
    gnss_baseline_s: float = 4.0
    vel_sigma_mps: float = 0.02
    rate_sigma_radps: float = 0.0005
    max_speed_mps: float = 0.5

    def __post_init__(self) -> None:
        positive(
            self,
            "window_s",
            "noise_factor",
            "max_rate_radps",
            "gnss_speed_mps",
            "gnss_baseline_s",
            "vel_sigma_mps",
            "rate_sigma_radps",
            "max_speed_mps",
        )


@dataclass(frozen=True)
class UkfParams:
    """Scaled unscented transform (Van der Merwe) of the total-state UKF (paper 001).

    Attributes:
        alpha: spread of the sigma points (paper 001: 0.99).
        beta: prior-distribution parameter (paper 001: 2, optimal for Gaussians).
        kappa: secondary scaling (paper 001: 0).
    """

    alpha: float = 0.99
    beta: float = 2.0
    kappa: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha <= 1.0:
            raise FieldError("alpha", "must be within (0, 1]")
        positive(self, "beta", "kappa", allow_zero=True)


@dataclass(frozen=True)
class InsFilterParams:
    """One INS/GNSS filter section, ``filters.<name>``.

    Attributes:
        imu_noise: IMU noise used when the dataset's meta.json declares none.
        init: initialization and alignment.
        gnss: GNSS measurement noise.
        clock: receiver clock model (tight coupling only; ignored otherwise).
        gating: innovation gating and timeout reset.
        step: time stepping.
        divergence: the NaN barrier.
        nhc: the non-holonomic constraint (required by and only by ``*_nhc`` filters).
        ukf: the unscented transform (required by and only by UKF filters).
        fuzzy: the fuzzy fading factor (required by and only by ``fwekf``, paper 004).
        iae: the innovation-based adaptive R (required by and only by ``iae_ekf``).
        integrity: the integrity monitor's tests (``core.integrity``).
        standstill: standstill detection and the ZUPT / ZARU updates at rest.
        smooth: also run the Rauch-Tung-Striebel backward pass over the run
            (``kernels.smoother``) and write ``smoothed.parquet`` beside the estimate.
    """

    imu_noise: ImuNoise
    init: InitParams
    gnss: GnssNoiseParams
    clock: ClockParams
    gating: GatingParams
    step: StepParams
    divergence: DivergenceParams
    nhc: NhcParams | None = None
    ukf: UkfParams | None = None
    fuzzy: FuzzyParams | None = None
    iae: IaeParams | None = None
    integrity: IntegrityParams = field(default_factory=IntegrityParams)
    standstill: StandstillParams = field(default_factory=StandstillParams)
    smooth: bool = False


@dataclass(frozen=True)
class FilterKind:
    """What a filter name means: estimator, coupling, NHC, and an adaptive weighting: the
    fuzzy fading of paper 004 (``fading``) or the innovation-based adaptive R (``iae``)."""

    estimator: Estimator
    coupling: Coupling
    nhc: bool
    fading: bool = False
    iae: bool = False

    @property
    def adaptive(self) -> bool:
        """Run by the adaptive kernel (``kernels.fwekf``)."""
        return self.fading or self.iae

    @property
    def numba_kernel(self) -> str:
        """``module:qualname`` of the numba kernel that runs this kind."""
        module, fn = (
            ("fwekf", "run_fwekf") if self.adaptive else (self.estimator, f"run_{self.estimator}")
        )
        return f"navreplay.pipeline.estimation.ins.kernels.{module}:{fn}"


FILTER_KINDS: dict[str, FilterKind] = {
    "lc_ekf": FilterKind("ekf", "loose", nhc=False),
    "tc_ekf": FilterKind("ekf", "tight", nhc=False),
    "tc_ukf": FilterKind("ukf", "tight", nhc=False),
    "lc_ekf_nhc": FilterKind("ekf", "loose", nhc=True),
    "tc_ekf_nhc": FilterKind("ekf", "tight", nhc=True),
    "tc_ukf_nhc": FilterKind("ukf", "tight", nhc=True),
    "fwekf": FilterKind("ekf", "loose", nhc=False, fading=True),
    "iae_ekf": FilterKind("ekf", "loose", nhc=False, iae=True),
}
