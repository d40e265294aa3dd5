"""Parameters of the ``multirotor_flight`` and ``bench_static`` datasets:
``synth.multirotor_flight`` in ``params.yaml`` (``pipeline.synth.multirotor``).

Kept free of heavy imports: ``pipeline.params`` loads these dataclasses for every stage. The
defaults are the values ``params.yaml`` holds (a test checks they agree).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.nav.local import LocalFrame
from navreplay.pipeline.synth.checks import require_non_negative, require_positive
from navreplay.pipeline.synth.seoul_params import ImuErrors

#: Consumer MEMS (a flight controller's ICM-42688 / BMI088 class IMU): 150 ug/rtHz and
#: 0.01 deg/s/rtHz white noise, turn-on biases of 0.08 m/s^2 and 0.2 deg/s (1 sigma per axis),
#: 0.2 % scale-factor errors.
CONSUMER_MEMS = ImuErrors(
    accel_noise_mps2_rthz=0.0015,
    gyro_noise_radps_rthz=0.000175,
    accel_bias_sigma_mps2=0.08,
    gyro_bias_sigma_radps=0.0035,
    accel_bias_rw_mps3_rthz=0.0003,
    gyro_bias_rw_radps2_rthz=0.00003,
    accel_scale_sigma_ppm=2000.0,
    gyro_scale_sigma_ppm=2000.0,
)


@dataclass(frozen=True)
class FlightPlan:
    """``flight``: the phases of the flight, in order (``pipeline.synth.multirotor``).

    Every change of velocity, yaw or figure-eight phase rate is a C2 quintic transition, so
    the acceleration is C1 and the attitude (thrust along the specific force) and body rates
    are continuous.

    Attributes:
        ground_s: at rest on the ground, armed, before take-off.
        climb_m: height of the hover above the ground.
        climb_rate_mps: vertical speed of the take-off.
        descent_rate_mps: vertical speed of the landing.
        vertical_ramp_s: time to reach (and leave) the climb and descent rates.
        hover_s: hover after the take-off and before the landing.
        pause_s: hover between the manoeuvres.
        yaw0_deg: heading on the ground, clockwise from north.
        yaw_turn_deg: yaw in place after the hover (positive: clockwise).
        yaw_turn_s: duration of that turn.
        sideways_speed_mps: the sideways leg: flown to the right of the body (body y along the
            track), after the yaw turn.
        sideways_s: time at that speed.
        backwards_speed_mps: the backwards leg (body -x along the track).
        backwards_s: time at that speed.
        speed_ramp_s: time to reach (and leave) the speed of a leg.
        eight_half_length_m: the figure eights (``A [sin s, sin(2s)/2]`` along and across
            ``eight_heading_deg``): half their length.
        eight_max_speed_mps: the speed at their crossing point (the fastest; the slowest,
            at the ends of the lobes, is about half).
        eight_climb_m: the height rises and falls by this over each eight (``-dz sin s``).
        eight_heading_deg: direction of their long axis.
        eights: how many eights are flown (they end where they started).
        eight_ramp_s: time to reach (and leave) the eights' phase rate.
        eight_yaw_turn_deg: yaw change while flying the eights (centred in them).
        eight_yaw_turn_s: duration of that change.
        landed_s: at rest on the ground after the landing.
    """

    ground_s: float = 20.0
    climb_m: float = 10.0
    climb_rate_mps: float = 2.0
    descent_rate_mps: float = 1.5
    vertical_ramp_s: float = 2.0
    hover_s: float = 5.0
    pause_s: float = 3.0
    yaw0_deg: float = 30.0
    yaw_turn_deg: float = 180.0
    yaw_turn_s: float = 8.0
    sideways_speed_mps: float = 4.0
    sideways_s: float = 8.0
    backwards_speed_mps: float = 3.0
    backwards_s: float = 6.0
    speed_ramp_s: float = 3.0
    eight_half_length_m: float = 30.0
    eight_max_speed_mps: float = 8.0
    eight_climb_m: float = 2.0
    eight_heading_deg: float = 120.0
    eights: int = 2
    eight_ramp_s: float = 6.0
    eight_yaw_turn_deg: float = -90.0
    eight_yaw_turn_s: float = 15.0
    landed_s: float = 15.0

    def __post_init__(self) -> None:
        require_non_negative(self, [n for n in self.__dataclass_fields__ if "deg" not in n])
        require_positive(
            self,
            [
                "climb_m",
                "climb_rate_mps",
                "descent_rate_mps",
                "vertical_ramp_s",
                "yaw_turn_s",
                "speed_ramp_s",
                "eight_half_length_m",
                "eight_max_speed_mps",
                "eights",
                "eight_ramp_s",
                "eight_yaw_turn_s",
            ],
        )
        for name in ("climb_rate_mps", "descent_rate_mps"):
            if getattr(self, name) * self.vertical_ramp_s > self.climb_m:
                raise FieldError(name, "too fast to reach within climb_m (x vertical_ramp_s)")
        if self.eight_yaw_turn_s > self.eights_s:
            raise FieldError("eight_yaw_turn_s", f"longer than the eights ({self.eights_s:.1f} s)")
        if self.eight_ramp_s >= self.eights_s - self.eight_ramp_s:
            raise FieldError("eight_ramp_s", "the eights are too short for their ramps")

    @property
    def eight_rate_radps(self) -> float:
        """The phase rate of the eights: the speed at the crossing point is the maximum."""
        a, dz = self.eight_half_length_m, self.eight_climb_m
        return self.eight_max_speed_mps / math.sqrt(2.0 * a * a + dz * dz)

    @property
    def eights_s(self) -> float:
        """Duration of the eights, ramps included (the phase runs over ``2 pi eights``)."""
        return 2.0 * math.pi * self.eights / self.eight_rate_radps + self.eight_ramp_s


@dataclass(frozen=True)
class TurnOnBias:
    """``turn_on_bias``: the constant IMU biases of this vehicle, body FRD, per axis.

    They replace the random draw of ``imu.*_bias_sigma`` (which stay the declared filter
    prior), so the test bed has turn-on biases of the size a consumer IMU shows, whatever the
    seed; the bias random walk, scale factors and noise are still drawn.

    Attributes:
        accel_mps2: accelerometer biases.
        gyro_dps: gyro biases, deg/s.
    """

    accel_mps2: tuple[float, float, float] = (0.06, -0.08, 0.05)
    gyro_dps: tuple[float, float, float] = (0.15, -0.25, 0.2)


@dataclass(frozen=True)
class MultirotorGnss:
    """``gnss``: the receiver's fixes (position, velocity and their accuracies).

    Attributes:
        h_sigma_m, v_sigma_m: 1-sigma of the position error per horizontal axis and up; the
            error is a first-order Gauss-Markov process per axis (``tau_s``). Reported as
            ``h_acc`` and ``v_acc``.
        vel_sigma_mps: white velocity noise per NED component; reported as the speed accuracy.
        tau_s: correlation time of the position error.
        num_sats: satellites used, reported with every fix.
        lever_arm_m: antenna relative to the IMU, body FRD.
    """

    h_sigma_m: float = 1.0
    v_sigma_m: float = 1.8
    vel_sigma_mps: float = 0.1
    tau_s: float = 20.0
    num_sats: int = 16
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, -0.12)

    def __post_init__(self) -> None:
        require_non_negative(self)
        require_positive(self, ["tau_s"])


@dataclass(frozen=True)
class MagParams:
    """``mag``: the magnetometer (HIGHRES_IMU ``xmag/ymag/zmag``).

    ``y = C_n^b B_n + hard_iron + w``, body FRD, gauss.

    Attributes:
        field_ned_gauss: the earth's field at the place (north, east, down). Default: the
            World Magnetic Model WMM2025 at the default origin (47.397742 N, 8.545594 E,
            0.488 km) on 2026-11-22, computed once with pygeomag 1.1.0: 21526, 1376, 43332 nT
            (declination +3.66 deg, inclination 63.54 deg, total 48404 nT).
        noise_gauss: white noise per axis and sample.
        hard_iron_gauss: constant offset in body FRD (an uncalibrated hard-iron residual).
    """

    field_ned_gauss: tuple[float, float, float] = (0.21526, 0.01376, 0.43332)
    noise_gauss: float = 0.002
    hard_iron_gauss: tuple[float, float, float] = (0.004, -0.003, 0.005)

    def __post_init__(self) -> None:
        require_non_negative(self, ["noise_gauss"])
        if math.hypot(self.field_ned_gauss[0], self.field_ned_gauss[1]) <= 0.0:
            raise FieldError("field_ned_gauss", "needs a horizontal component")

    @property
    def declination_deg(self) -> float:
        return math.degrees(math.atan2(self.field_ned_gauss[1], self.field_ned_gauss[0]))


@dataclass(frozen=True)
class BenchParams:
    """``bench``: the ``bench_static`` dataset: the same vehicle and sensors on a bench
    indoors, at rest the whole time, its receiver without a fix.

    Attributes:
        duration_s: length of the log.
        roll_deg, pitch_deg, yaw_deg: the attitude on the (not quite level) bench.
        fix_type: GPS_RAW_INT fix type reported (0: no GPS, 1: no fix).
        num_sats: satellites reported (fewer than a fix needs).
    """

    duration_s: float = 60.0
    roll_deg: float = 1.0
    pitch_deg: float = -1.5
    yaw_deg: float = 75.0
    fix_type: int = 1
    num_sats: int = 3

    def __post_init__(self) -> None:
        require_positive(self, ["duration_s"])
        if self.fix_type not in (0, 1):
            raise FieldError("fix_type", "a bench log without a fix has 0 (no GPS) or 1 (no fix)")
        if not 0 <= self.num_sats < 4:
            raise FieldError("num_sats", "must be 0..3 (no fix)")


@dataclass(frozen=True)
class MultirotorFlightParams:
    """``synth.multirotor_flight`` (``pipeline.synth.multirotor``).

    Attributes:
        imu_rate_hz: HIGHRES_IMU rate (and the magnetometer's).
        gnss_rate_hz: GPS_RAW_INT rate; must divide the IMU rate.
        truth_rate_hz: SIM_STATE truth rate; must divide the IMU rate.
        flight: the flight's phases.
        imu: the IMU error model (``pipeline.synth.imu.corrupt``) and the declared noise model.
        turn_on_bias: the IMU's constant biases (instead of a draw of ``imu``'s sigmas).
        gnss: the receiver.
        mag: the magnetometer.
        bench: the ``bench_static`` variant.
        origin: the take-off point (ground level, ellipsoidal height).
        start_unix_s: UNIX time of the first sample.
    """

    imu_rate_hz: int = 200
    gnss_rate_hz: int = 5
    truth_rate_hz: int = 50
    flight: FlightPlan = field(default_factory=FlightPlan)
    imu: ImuErrors = CONSUMER_MEMS
    turn_on_bias: TurnOnBias = field(default_factory=TurnOnBias)
    gnss: MultirotorGnss = field(default_factory=MultirotorGnss)
    mag: MagParams = field(default_factory=MagParams)
    bench: BenchParams = field(default_factory=BenchParams)
    origin: LocalFrame = field(default_factory=lambda: LocalFrame(47.397742, 8.545594, 488.0))
    start_unix_s: int = 1795348800

    def __post_init__(self) -> None:
        if self.imu_rate_hz <= 0 or 1_000_000 % self.imu_rate_hz:
            raise FieldError("imu_rate_hz", "must be > 0 and divide 1e6 us evenly")
        for name in ("gnss_rate_hz", "truth_rate_hz"):
            rate = getattr(self, name)
            if rate <= 0 or self.imu_rate_hz % rate:
                raise FieldError(name, "must be > 0 and divide imu_rate_hz")
