"""The John Deere 8400 tractor of paper 000 as a step-by-step simulator with its sensors.

Plant (paper 000 eq. 1-4, Table 3 at 3 m/s), state
``[E, N, V_x, psi, psi_dot, psi_ddot, delta, delta_dot]`` (eq. 6)::

    E_dot = V_x sin(psi)                  N_dot = V_x cos(psi)                (eq. 1-2)
    psi_dddot = -2 zeta w_n psi_ddot - w_n^2 psi_dot + K_R w_n^2 delta         (eq. 3)
    delta_ddot = -delta_dot / tau_v + K_v / tau_v u                            (eq. 4)

Eq. 3 is printed in the paper as an equation in ``psi``; its ``A_c`` (eq. 11) and ``J_2``
(eq. 19) make it a second-order lag from steer angle to *yaw rate* (DC gain ``K_R``), which is
the physically meaningful reading (a constant steer angle gives a constant yaw rate) and the
one implemented. ``V_x`` is constant. The command ``u`` is held over each sample period (zero-
order hold); the linear yaw/steer part is advanced with its exact discretization and
East/North with 3-point Gauss-Legendre quadrature of ``V_x sin/cos psi(t)`` inside the step, so
the plant is integrated to round-off.

Sensors (paper 000 Table 2 variances, section 4 biases), all sampled at every step::

    RTK GPS           E + n, N + n                       (NaN while GPS is unavailable)
    multi-antenna     psi + psi_b + n, wrapped to [-pi, pi)   (NaN while unavailable)
    FOG yaw rate      psi_dot + g_b + n
    potentiometer     delta + delta_b + n
    Doppler radar     V_x + r_b + n

Six standard normals are drawn every step in that order whether or not GPS is available, so an
outage changes which values are seen, never the noise of the others: a run with an outage and
the nominal run with the same seed are paired sample by sample.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.control.lqr import (
    StraightLine,
    YawSteerModel,
    discretize,
    yaw_steer_model,
)
from navreplay.pipeline.nav.local import LocalFrame
from navreplay.pipeline.synth.checks import require_non_negative

F64 = npt.NDArray[np.float64]

# 3-point Gauss-Legendre nodes on [0, 1] and weights (sum 1).
_GL_NODES = (0.5 - math.sqrt(15.0) / 10.0, 0.5, 0.5 + math.sqrt(15.0) / 10.0)
_GL_WEIGHTS = (5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0)


@dataclass(frozen=True)
class TractorBiases:
    """Constant sensor biases (paper 000 section 4: 0.1, 0.2, 0.3, 0.4)."""

    steer_rad: float = 0.1
    heading_rad: float = 0.2
    gyro_radps: float = 0.3
    radar_mps: float = 0.4


@dataclass(frozen=True)
class TractorNoiseVariances:
    """White sensor noise variances per sample (paper 000 Table 2)."""

    east_m2: float = 9.0e-4
    north_m2: float = 9.0e-4
    heading_rad2: float = 1.745e-3
    yaw_rate_rad2ps2: float = 6.0e-5
    steer_rad2: float = 1.5e-3
    speed_m2ps2: float = 1.4e-2

    def __post_init__(self) -> None:
        require_non_negative(self, message="a variance must be >= 0")

    def sigmas(self) -> F64:
        """Standard deviations in draw order: E, N, heading, yaw rate, steer, speed."""
        return np.sqrt(
            [
                self.east_m2,
                self.north_m2,
                self.heading_rad2,
                self.yaw_rate_rad2ps2,
                self.steer_rad2,
                self.speed_m2ps2,
            ]
        )


@dataclass(frozen=True)
class TractorStraightParams:
    """``synth.tractor_straight``: the paper 000 scenario (defaults are the paper's values).

    Attributes:
        rate_hz: simulation, control and sensor rate (paper: 50 Hz).
        duration_s: length of the recording (paper: 80 s).
        speed_mps: constant forward speed ``V_x`` (paper: 3 m/s; Table 3 holds for it).
        line_east_m: East offset of the desired line from the start point (the 3 m step).
        line_heading_deg: desired heading ``psi_d`` (paper: 0, due North).
        model: yaw and steering dynamics (Table 3).
        biases: sensor biases.
        noise: sensor noise variances (Table 2).
        origin: geodetic origin of the East/North map (the start point).
        start_unix_s: UNIX time of the first sample.
    """

    rate_hz: int = 50
    duration_s: float = 80.0
    speed_mps: float = 3.0
    line_east_m: float = 3.0
    line_heading_deg: float = 0.0
    model: YawSteerModel = field(default_factory=YawSteerModel)
    biases: TractorBiases = field(default_factory=TractorBiases)
    noise: TractorNoiseVariances = field(default_factory=TractorNoiseVariances)
    origin: LocalFrame = field(default_factory=lambda: LocalFrame(40.47, -86.99, 160.0))
    start_unix_s: int = 1795338000

    def __post_init__(self) -> None:
        if self.rate_hz <= 0 or 1_000_000 % self.rate_hz:
            raise FieldError("rate_hz", "must be > 0 and divide 1e6 us evenly")
        if self.duration_s <= 0:
            raise FieldError("duration_s", "must be > 0")
        if self.speed_mps <= 0:
            raise FieldError("speed_mps", "must be > 0")

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def dt_ns(self) -> int:
        return 1_000_000_000 // self.rate_hz

    @property
    def steps(self) -> int:
        """Number of steps of the recording (samples = steps + 1)."""
        return round(self.duration_s * self.rate_hz)

    def line(self) -> StraightLine:
        """The desired line: through (line_east_m, 0) with heading line_heading_deg."""
        return StraightLine(self.line_east_m, 0.0, math.radians(self.line_heading_deg))


class TractorState(NamedTuple):
    """True plant state at time ``t_s`` (heading continuous, not wrapped)."""

    t_s: float
    east_m: float
    north_m: float
    speed_mps: float
    heading_rad: float
    yaw_rate_radps: float
    yaw_accel_radps2: float
    steer_rad: float
    steer_rate_radps: float


class TractorMeasurement(NamedTuple):
    """All sensor readings at time ``t_s``; GPS fields are NaN when ``gps_valid`` is False."""

    t_s: float
    gps_valid: bool
    east_m: float
    north_m: float
    heading_rad: float
    yaw_rate_radps: float
    steer_rad: float
    speed_mps: float


def wrap_pi(angle: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class TractorSim:
    """The tractor plant and sensors, advanced one sample period per ``step``.

    Usage (closed loop on estimates, as the cascaded-filter issue does)::

        sim = TractorSim(params, seed, gps_outages_s=[(30.0, 40.0)])
        z = sim.measurement                 # readings at t = 0
        for _ in range(params.steps):
            u = controller(z)               # e.g. lqr_command(K, filter.control_state())
            z = sim.step(u)                 # plant advanced to t + dt, readings there

    Args:
        params: scenario, plant and sensor parameters.
        seed: seeds the sensor noise (an int or a ``SeedSequence``); same seed, same noise.
        gps_outages_s: half-open windows ``[start, end)`` in seconds from the start during
            which GPS (E, N, heading) is unavailable; ``step(u, gps=...)`` overrides per step.
        initial: the plant state at t = 0 (its ``t_s`` and ``speed_mps`` are ignored); default
            at the origin heading North with yaw and steering at rest, as in the paper.
    """

    def __init__(
        self,
        params: TractorStraightParams,
        seed: int | np.random.SeedSequence,
        *,
        gps_outages_s: Sequence[tuple[float, float]] = (),
        initial: TractorState | None = None,
    ) -> None:
        self.params = params
        self._rng = np.random.default_rng(seed)
        self._sigma = params.noise.sigmas()
        b = params.biases
        self._bias = (b.heading_rad, b.gyro_radps, b.steer_rad, b.radar_mps)
        self.gps_outages_s = tuple((float(a), float(e)) for a, e in gps_outages_s)
        for a, e in self.gps_outages_s:
            if not e > a:
                raise ValueError(f"GPS outage window ({a}, {e}) must have end > start")
        self._dt = params.dt_s
        self._k = 0
        self._east = 0.0 if initial is None else float(initial.east_m)
        self._north = 0.0 if initial is None else float(initial.north_m)
        # linear part z = [psi, psi_dot, psi_ddot, delta, delta_dot]
        self._z = np.zeros(5) if initial is None else np.array(initial[4:], dtype=np.float64)
        self._phi, self._gamma = _yaw_steer_discrete(params.model, self._dt)
        nodes = [_yaw_steer_discrete(params.model, s * self._dt) for s in _GL_NODES]
        # heading at the quadrature nodes: psi(s) = phi_s[0] @ z + gamma_s[0] u
        self._psi_rows = np.array([p[0] for p, _ in nodes])
        self._psi_gain = np.array([g[0, 0] for _, g in nodes])
        self._measurement = self._measure(None)

    @property
    def t_s(self) -> float:
        """Current time, s from the start."""
        return self._k / self.params.rate_hz

    @property
    def step_index(self) -> int:
        return self._k

    @property
    def frame(self) -> LocalFrame:
        """The East/North map (origin at the start point)."""
        return self.params.origin

    @property
    def line(self) -> StraightLine:
        return self.params.line()

    @property
    def biases(self) -> TractorBiases:
        return self.params.biases

    @property
    def truth(self) -> TractorState:
        z = self._z
        return TractorState(
            self.t_s,
            self._east,
            self._north,
            self.params.speed_mps,
            float(z[0]),
            float(z[1]),
            float(z[2]),
            float(z[3]),
            float(z[4]),
        )

    @property
    def measurement(self) -> TractorMeasurement:
        """The readings at the current time (drawn once per step)."""
        return self._measurement

    def gps_scheduled(self, t_s: float) -> bool:
        """Whether GPS is available at ``t_s`` under the outage windows."""
        return not any(a <= t_s < e for a, e in self.gps_outages_s)

    def step(self, u: float, *, gps: bool | None = None) -> TractorMeasurement:
        """Apply command ``u`` (eq. 4, held for one period) and return the readings at t + dt.

        Args:
            u: steering-valve command (rad/s of steer rate at K_v = 1).
            gps: force GPS availability for the new readings; None follows the outage windows.
        """
        u = float(u)
        if not math.isfinite(u):
            raise ValueError(f"non-finite steering command {u!r} at t = {self.t_s:.3f} s")
        v = self.params.speed_mps
        psi_nodes = self._psi_rows @ self._z + self._psi_gain * u
        s = c = 0.0
        for w, p in zip(_GL_WEIGHTS, psi_nodes.tolist(), strict=True):
            s += w * math.sin(p)
            c += w * math.cos(p)
        self._east += v * self._dt * s
        self._north += v * self._dt * c
        self._z = self._phi @ self._z + self._gamma[:, 0] * u
        self._k += 1
        self._measurement = self._measure(gps)
        return self._measurement

    def _measure(self, gps: bool | None) -> TractorMeasurement:
        n = self._rng.standard_normal(6) * self._sigma
        t = self.t_s
        ok = self.gps_scheduled(t) if gps is None else bool(gps)
        psi_b, g_b, d_b, r_b = self._bias
        z = self._z
        nan = math.nan
        return TractorMeasurement(
            t,
            ok,
            self._east + n[0] if ok else nan,
            self._north + n[1] if ok else nan,
            wrap_pi(z[0] + psi_b + n[2]) if ok else nan,
            float(z[1] + g_b + n[3]),
            float(z[3] + d_b + n[4]),
            float(self.params.speed_mps + r_b + n[5]),
        )


def _yaw_steer_discrete(model: YawSteerModel, dt_s: float) -> tuple[F64, F64]:
    """Exact ZOH discretization of the yaw/steer part ``[psi, psi_dot, psi_ddot, delta,
    delta_dot]`` of eq. 3-4 over ``dt_s``."""
    return discretize(*yaw_steer_model(model), dt_s)
