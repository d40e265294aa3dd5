"""Typed parameters of the vehicle-model filters (paper 003): ``filters.vehicle_*``.

All four filters (``vehicle_kinematic``, ``vehicle_dynamic``, ``vehicle_switched``,
``vehicle_imm``) take one ``VehicleFilterParams`` section; the name fixes the mode. The car
itself (``vehicle``) has the fields of ``synth.car_speed_ramp.vehicle`` so params.yaml can share
them with the synthesizer through a YAML anchor (the quasi-static dynamic model does not use
the yaw inertia).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Literal

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.estimation.core.checks import positive
from navreplay.pipeline.estimation.core.integrity import IntegrityParams
from navreplay.pipeline.synth.bicycle import VehicleParams

VEHICLE_FILTERS = ("vehicle_kinematic", "vehicle_dynamic", "vehicle_switched", "vehicle_imm")


@dataclass(frozen=True)
class VehicleNoiseParams:
    """Input and model noise.

    Attributes:
        wheel_speed_sigma_mps: wheel-speed input 1-sigma per sample, m/s.
        steer_sigma_rad: steering-angle input 1-sigma per sample (also the virtual steering
            from the yaw rate when the log has no steering angle), rad.
        yaw_rate_sigma_radps: yaw-rate measurement 1-sigma, rad/s.
        speed_psd_m2ps3: white model-error density on the speed state, (m/s)^2/s.
        slip_psd_rad2ps: on the sideslip, rad^2/s.
        heading_psd_rad2ps: on the heading, rad^2/s.
        position_psd_m2ps: on north and east, m^2/s.
    """

    wheel_speed_sigma_mps: float = 0.05
    steer_sigma_rad: float = 0.002
    yaw_rate_sigma_radps: float = 0.005
    speed_psd_m2ps3: float = 0.01
    slip_psd_rad2ps: float = 1.0e-4
    heading_psd_rad2ps: float = 1.0e-4
    position_psd_m2ps: float = 0.01

    def __post_init__(self) -> None:
        positive(self, "wheel_speed_sigma_mps", "steer_sigma_rad", "yaw_rate_sigma_radps")
        positive(
            self, "speed_psd_m2ps3", "slip_psd_rad2ps", "heading_psd_rad2ps", "position_psd_m2ps"
        )


@dataclass(frozen=True)
class VehicleGnssParams:
    """GPS measurements: position, speed and course (paper 003 eq. 20).

    Attributes:
        pos_sigma_floor_m: floor on the reported horizontal accuracy, m.
        pos_sigma_default_m: horizontal 1-sigma when none is reported, m.
        vel_sigma_floor_mps: floor on the reported speed accuracy, m/s.
        vel_sigma_default_mps: speed 1-sigma when none is reported, m/s.
        course_min_speed_mps: the course is fused only above this GPS speed, m/s (its
            1-sigma is the velocity 1-sigma over the speed).
        use_speed: fuse the GPS speed.
        use_course: fuse the GPS course.
    """

    pos_sigma_floor_m: float = 0.5
    pos_sigma_default_m: float = 3.0
    vel_sigma_floor_mps: float = 0.05
    vel_sigma_default_mps: float = 0.2
    course_min_speed_mps: float = 1.0
    use_speed: bool = True
    use_course: bool = True

    def __post_init__(self) -> None:
        positive(self, "pos_sigma_floor_m", "pos_sigma_default_m", "vel_sigma_floor_mps")
        positive(self, "vel_sigma_default_mps", "course_min_speed_mps")


@dataclass(frozen=True)
class SwitchingParams:
    """Speed-based model selection with hysteresis (``vehicle_switched``).

    Attributes:
        speed_up_mps: switch from the kinematic to the dynamic model above this wheel speed.
        speed_down_mps: switch back below this wheel speed (< ``speed_up_mps``).
    """

    speed_up_mps: float = 8.0
    speed_down_mps: float = 6.0

    def __post_init__(self) -> None:
        positive(self, "speed_up_mps", "speed_down_mps")
        if self.speed_down_mps >= self.speed_up_mps:
            raise FieldError("speed_down_mps", "must be below speed_up_mps (hysteresis)")


@dataclass(frozen=True)
class ImmParams:
    """Interacting multiple model (``vehicle_imm``).

    Attributes:
        p_stay_kinematic: Markov probability of staying in the kinematic model per step.
        p_stay_dynamic: the same for the dynamic model.
        mu0_dynamic: initial probability of the dynamic model.
        likelihood_floor: smallest model likelihood (keeps a probability from reaching 0).
    """

    p_stay_kinematic: float = 0.99
    p_stay_dynamic: float = 0.99
    mu0_dynamic: float = 0.5
    likelihood_floor: float = 1.0e-300

    def __post_init__(self) -> None:
        for name in ("p_stay_kinematic", "p_stay_dynamic", "mu0_dynamic"):
            if not 0.0 < getattr(self, name) < 1.0:
                raise FieldError(name, "must be within (0, 1)")
        positive(self, "likelihood_floor")


@dataclass(frozen=True)
class VehicleInitParams:
    """Initialization: position from a GPS fix, heading from the GPS course or from the
    displacement between two fixes at least ``align_distance_m`` apart by the wheel odometer
    and consistent with it (``vehicle.replay._heading_from_fixes``).

    Attributes:
        align_distance_m: shortest displacement that gives the heading (no GPS course), m.
        align_window_s: longest time between those two fixes, s.
        speed_sigma_mps: initial speed 1-sigma, m/s.
        slip_sigma_rad: initial sideslip 1-sigma, rad.
        heading_sigma_floor_rad: floor on the initial heading 1-sigma, rad.
    """

    align_distance_m: float = 10.0
    align_window_s: float = 10.0
    speed_sigma_mps: float = 0.3
    slip_sigma_rad: float = 0.05
    heading_sigma_floor_rad: float = 0.02

    def __post_init__(self) -> None:
        positive(self, *(f.name for f in fields(self)))


@dataclass(frozen=True)
class VehicleFilterParams:
    """One ``filters.vehicle_*`` section.

    Attributes:
        vehicle: mass, geometry, tire stiffness (``synth.bicycle.VehicleParams``).
        noise: input and model noise.
        gnss: GPS measurement noise and use.
        switching: the speed thresholds of ``vehicle_switched``.
        imm: the Markov model of ``vehicle_imm``.
        init: initialization.
        max_step_s: longest single prediction step, s.
        output_interval_s: output grid, s.
        gate_probability: chi-square gate per measurement block.
        gate_timeout_s: a stream rejected for longer than this resets the covariance of the
            states it observes (bad-inputs F2), s.
        on_divergence: ``raise`` or ``flag``.
        max_pos_sigma_m: a larger horizontal position 1-sigma is a divergence, m.
        integrity: the integrity monitor's tests (``core.integrity``).
    """

    vehicle: VehicleParams
    noise: VehicleNoiseParams
    gnss: VehicleGnssParams
    switching: SwitchingParams
    imm: ImmParams
    init: VehicleInitParams
    max_step_s: float = 0.02
    output_interval_s: float = 0.1
    gate_probability: float = 0.9999
    gate_timeout_s: float = 2.0
    on_divergence: Literal["raise", "flag"] = "raise"
    max_pos_sigma_m: float = 1.0e4
    integrity: IntegrityParams = field(default_factory=IntegrityParams)

    def __post_init__(self) -> None:
        positive(self, "max_step_s", "output_interval_s", "max_pos_sigma_m", "gate_timeout_s")
        if not 0.5 < self.gate_probability < 1.0:
            raise FieldError("gate_probability", "must be within (0.5, 1)")
