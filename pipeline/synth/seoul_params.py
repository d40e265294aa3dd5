"""Parameters of the ``seoul_campus`` synthesizer: ``synth.seoul_campus`` in ``params.yaml``.

Kept free of heavy imports: ``pipeline.params`` loads these dataclasses for every stage. Every
value lives in ``params.yaml`` (no defaults here, so the file is the one place to tune them);
tests take the file's values and change fields with ``dataclasses.replace``. Setting
``noise_free`` (or zeroing individual sigmas) removes the random errors; deterministic effects
(receiver clock offset and drift at the start, satellite clocks, lever arm) stay, and so do the
accuracies the receiver reports (``pseudorange_std_m``, ``h_acc_m`` ...).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.synth.checks import require_non_negative, require_positive

if TYPE_CHECKING:
    from navreplay.ingest.config import ImuNoise


@dataclass(frozen=True)
class ImuErrors:
    """``imu``: the IMU error model (``pipeline.synth.imu``); zero disables a term.

    Attributes:
        accel_noise_mps2_rthz: accelerometer white noise density, m/s^2/sqrt(Hz).
        gyro_noise_radps_rthz: gyro white noise density, rad/s/sqrt(Hz).
        accel_bias_sigma_mps2: 1-sigma of the constant accelerometer bias, m/s^2.
        gyro_bias_sigma_radps: 1-sigma of the constant gyro bias, rad/s.
        accel_bias_rw_mps3_rthz: accelerometer bias random walk, m/s^3/sqrt(Hz).
        gyro_bias_rw_radps2_rthz: gyro bias random walk, rad/s^2/sqrt(Hz).
        accel_scale_sigma_ppm: 1-sigma of the constant accelerometer scale-factor error, ppm.
        gyro_scale_sigma_ppm: 1-sigma of the constant gyro scale-factor error, ppm.
    """

    accel_noise_mps2_rthz: float
    gyro_noise_radps_rthz: float
    accel_bias_sigma_mps2: float
    gyro_bias_sigma_radps: float
    accel_bias_rw_mps3_rthz: float
    gyro_bias_rw_radps2_rthz: float
    accel_scale_sigma_ppm: float
    gyro_scale_sigma_ppm: float

    def __post_init__(self) -> None:
        require_non_negative(self)

    def noise_model(self) -> ImuNoise:
        """The matching filter noise model (``ingest.config.ImuNoise``; no scale factors)."""
        from navreplay.ingest.config import ImuNoise

        return ImuNoise(
            accel_noise_mps2_rthz=self.accel_noise_mps2_rthz,
            gyro_noise_radps_rthz=self.gyro_noise_radps_rthz,
            accel_bias_sigma_mps2=self.accel_bias_sigma_mps2,
            gyro_bias_sigma_radps=self.gyro_bias_sigma_radps,
            accel_bias_rw_mps3_rthz=self.accel_bias_rw_mps3_rthz,
            gyro_bias_rw_radps2_rthz=self.gyro_bias_rw_radps2_rthz,
        )


@dataclass(frozen=True)
class ReceiverParams:
    """``gnss``: the GNSS receiver (``pipeline.synth.gnss``).

    Attributes:
        elevation_mask_deg: satellites below are not tracked.
        cn0_zenith_dbhz: C/N0 at zenith; C/N0(el) = zenith + cn0_slope_db * log10(sin el).
        cn0_slope_db: see above (18 dB: 34 dB-Hz at 10 deg for 48 at zenith).
        cn0_sigma_db: white noise on the reported C/N0.
        cn0_ref_dbhz: C/N0 at which the noise sigmas below apply; they scale as
            10^((cn0_ref - cn0) / 20), i.e. with 1/sqrt(C/N0).
        pr_sigma_m: pseudorange white noise at ``cn0_ref_dbhz``, m.
        prr_sigma_mps: pseudorange-rate white noise at ``cn0_ref_dbhz``, m/s.
        clock_bias0_m: receiver clock bias at the start, m.
        clock_drift0_mps: receiver clock drift at the start, m/s.
        clock_bias_rw_m_rths: white frequency noise of the clock, sqrt(q_b) (TCXO: ~0.1).
        clock_drift_rw_mps_rths: random-walk frequency noise, sqrt(q_d) (TCXO: ~0.2).
        fix_uere_m: user range error behind the fixes: position error sigma = UERE * DOP.
        fix_tau_s: correlation time of the fix position errors (first-order Gauss-Markov).
        fix_vel_sigma_mps: white noise on each fix velocity component.
    """

    elevation_mask_deg: float
    cn0_zenith_dbhz: float
    cn0_slope_db: float
    cn0_sigma_db: float
    cn0_ref_dbhz: float
    pr_sigma_m: float
    prr_sigma_mps: float
    clock_bias0_m: float
    clock_drift0_mps: float
    clock_bias_rw_m_rths: float
    clock_drift_rw_mps_rths: float
    fix_uere_m: float
    fix_tau_s: float
    fix_vel_sigma_mps: float

    def __post_init__(self) -> None:
        require_non_negative(
            self,
            (
                "cn0_sigma_db",
                "pr_sigma_m",
                "prr_sigma_mps",
                "clock_bias_rw_m_rths",
                "clock_drift_rw_mps_rths",
                "fix_uere_m",
                "fix_vel_sigma_mps",
            ),
        )
        if not 0.0 <= self.elevation_mask_deg < 90.0:
            raise FieldError("elevation_mask_deg", "must be within [0, 90)")
        if self.fix_tau_s <= 0:
            raise FieldError("fix_tau_s", "must be > 0")


@dataclass(frozen=True)
class ConstellationParams:
    """``constellation``: the broadcast GPS constellation (``pipeline.synth.constellation``).

    Attributes:
        eccentricity: orbit eccentricity of every slot (SPS PS: 0.00-0.02).
        arg_perigee_deg: argument of perigee of every slot.
        upload_interval_s: spacing of toe between successive ephemeris sets.
        af0_sigma_s: spread of the satellite clock offsets (drawn once per dataset).
        af1_sigma_sps: spread of the satellite clock drifts.
        tgd_sigma_s: spread of the group delays TGD.
    """

    eccentricity: float
    arg_perigee_deg: float
    upload_interval_s: int
    af0_sigma_s: float
    af1_sigma_sps: float
    tgd_sigma_s: float

    def __post_init__(self) -> None:
        require_non_negative(self)
        if self.eccentricity >= 0.05:
            raise FieldError("eccentricity", "must be within [0, 0.05)")
        if not 16 <= self.upload_interval_s <= 14_400:
            raise FieldError("upload_interval_s", "must be within 16..14400 s")


@dataclass(frozen=True)
class SeoulCampusParams:
    """``synth.seoul_campus``: the campus drive of paper 001 (``pipeline.synth.seoul_campus``).

    Attributes:
        start_gps: calendar time of the first sample on the GPS scale, whole seconds.
        duration_s: length of the drive, s (the route repeats if it is shorter).
        stationary_s: rest at the start, for alignment, s.
        lat_deg, lon_deg, alt_m: start position of the IMU (ellipsoidal height).
        yaw_deg: heading at the start.
        imu_rate_hz: IMU (and truth) sample rate; a multiple of ``gnss_rate_hz``.
        gnss_rate_hz: fix and observation rate.
        lever_arm_m: GNSS antenna relative to the IMU, body FRD, m.
        roll_per_lat_acc_rad: body roll out of a turn per m/s^2 of lateral acceleration.
        max_accel_mps2: peak longitudinal acceleration.
        max_yaw_accel_radps2: peak yaw acceleration into and out of turns.
        max_grade_rate_ps: peak rate of change of the road grade, 1/s.
        noise_free: remove every random error (IMU, receiver clock noise, observables, fixes).
        imu: IMU errors. gnss: receiver. constellation: satellites.
        sideslip_per_lat_acc_rad: the body's sideslip into a turn per m/s^2 of lateral
            acceleration (``trajectory.Body``); 0: the idealised car, which obeys the
            non-holonomic constraint exactly.
        pitch_per_long_acc_rad: suspension pitch per m/s^2 of acceleration (nose up).
        road_rms_m: the road profile's RMS as the body follows it (0: a flat road).
    """

    start_gps: str
    duration_s: float
    stationary_s: float
    lat_deg: float
    lon_deg: float
    alt_m: float
    yaw_deg: float
    imu_rate_hz: int
    gnss_rate_hz: int
    lever_arm_m: tuple[float, float, float]
    roll_per_lat_acc_rad: float
    max_accel_mps2: float
    max_yaw_accel_radps2: float
    max_grade_rate_ps: float
    noise_free: bool
    imu: ImuErrors
    gnss: ReceiverParams
    constellation: ConstellationParams
    sideslip_per_lat_acc_rad: float = 0.0
    pitch_per_long_acc_rad: float = 0.0
    road_rms_m: float = 0.0

    def __post_init__(self) -> None:
        try:
            stamp = np.datetime64(self.start_gps, "ns")
        except ValueError as err:
            raise FieldError("start_gps", f"not an ISO time: {err}") from err
        if stamp != stamp.astype("datetime64[s]"):
            raise FieldError("start_gps", "must be whole seconds")
        if self.duration_s <= 0:
            raise FieldError("duration_s", "must be > 0")
        if self.stationary_s < 0:
            raise FieldError("stationary_s", "must be >= 0 (>= duration_s: at rest throughout)")
        if self.imu_rate_hz <= 0 or self.gnss_rate_hz <= 0:
            raise FieldError("imu_rate_hz", "rates must be positive")
        if self.imu_rate_hz % self.gnss_rate_hz or 1_000_000_000 % self.imu_rate_hz:
            raise FieldError("imu_rate_hz", "must be a multiple of gnss_rate_hz dividing 1 GHz")
        require_positive(self, ("max_accel_mps2", "max_yaw_accel_radps2", "max_grade_rate_ps"))
        require_non_negative(self, ("road_rms_m",))


NO_IMU_ERRORS = ImuErrors(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
