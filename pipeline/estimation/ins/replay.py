"""One replay loop for every INS/GNSS filter: tables in, a ``RunResult`` out.

``run_filter`` prepares the inputs behind the data barrier (``inputs``), splits the IMU into
segments at long gaps, aligns each segment (``alignment``), builds the stop schedule (output
grid + update epochs + NHC slots) and hands arrays to a backend:

- ``numba`` (default): ``kernels.ekf.run_ekf`` / ``kernels.ukf.run_ukf``, the whole loop
  compiled (``cache=True``);
- ``filterpy``: ``reference.run_ekf_filterpy`` / ``reference.run_ukf_filterpy``, the same
  model functions, gating and bookkeeping driven by filterpy's ExtendedKalmanFilter and
  UnscentedKalmanFilter, with the same signature and outputs.

A divergence (NaN barrier, indefinite covariance, limits) raises ``DivergenceError`` or, with
``divergence.on_divergence: flag``, ends the run there and marks it diverged.
"""

from __future__ import annotations

import importlib
import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numba as nb
import numpy as np
import pyarrow as pa

from navreplay.ingest.config import ImuNoise
from navreplay.ingest.meta import SensorMeta
from navreplay.pipeline._numba_cache import fewer_gc_passes
from navreplay.pipeline.distributions import chi2_ppf
from navreplay.pipeline.errors import DivergenceError
from navreplay.pipeline.estimation.core import gating as gt
from navreplay.pipeline.estimation.core import runlog as rl
from navreplay.pipeline.estimation.core import tables as tb
from navreplay.pipeline.estimation.core.contract import Backend
from navreplay.pipeline.estimation.core.runlog import RunLog
from navreplay.pipeline.estimation.core.tables import ReplayInputError
from navreplay.pipeline.estimation.core.unscented import ukf_weights
from navreplay.pipeline.estimation.ins import inputs as inp
from navreplay.pipeline.estimation.ins import standstill
from navreplay.pipeline.estimation.ins.alignment import (
    COURSE_IS_HEADING,
    Alignment,
    align,
    why_not_aligned,
)
from navreplay.pipeline.estimation.ins.config import (
    FILTER_KINDS,
    FilterKind,
    GnssNoiseParams,
    InsFilterParams,
)
from navreplay.pipeline.estimation.ins.fixnoise import FixNoise, ObsNoise
from navreplay.pipeline.estimation.ins.fuzzy import FZ_MODE, MODE_IAE
from navreplay.pipeline.estimation.ins.kernels import smoother as sm_kernel
from navreplay.pipeline.estimation.ins.kernels.records import (
    Fading,
    Schedule,
    Settings,
    SmoothLog,
)
from navreplay.pipeline.estimation.ins.models import ins, ins_errors
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.nav.earth import F64, I64

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FilterSetup:
    """Everything a backend needs besides the data: one filter's resolved settings."""

    name: str
    estimator: str
    settings: Settings
    adaptive: F64 | None = None  # fwekf's fuzzy system or iae_ekf's window (``fuzzy.FZ_*``)

    @property
    def n(self) -> int:
        """The error-state dimension."""
        return self.settings.n

    @property
    def lever_b(self) -> F64:
        """The antenna lever arm, body FRD, m (3,)."""
        return self.settings.lever_b


@dataclass
class RunResult:
    """The outcome of one filter run.

    Attributes:
        filter: filter name; backend: ``numba`` or ``filterpy``; n: error-state dimension.
        t_ns: output times (K,); x: full states (K, 18); P: error covariances (K, n, n).
        inn_i: innovation rows (J, 5): t_ns, stream, sv code, dim, accepted.
        inn_f: innovation rows (J, 8): nis, gate, innovation[3], innovation sigma[3].
        events: data and filter events, by time.
        alignments: one per aligned segment.
        status: ``ok`` or ``diverged``; failure: what diverged, and when.
        runtime_s: wall time of the replay (inputs, alignment, filter), without compile_s.
        compile_s: time spent compiling the kernel or loading it from numba's cache.
        duration_s: span of IMU time replayed.
        extra: filter-specific series (fwekf: ``alpha``).
        imu_noise: the IMU noise densities used and their ``source`` (``resolve_imu_noise``).
        fix_noise: the fix-error model a loosely coupled run used (``fixnoise.FixNoise``).
        obs_noise: the pseudorange noise a tightly coupled run used (``fixnoise.ObsNoise``).
        smoothed: the RTS-smoothed ``x`` and ``P`` at the same output rows, if the run was
            smoothed (``filters.<name>.smooth``); smoothing: how (``Smoothing``).
    """

    filter: str
    backend: str
    n: int
    t_ns: I64
    x: F64
    P: F64
    inn_i: I64
    inn_f: F64
    events: list[tb.Event]
    alignments: list[Alignment]
    status: str = "ok"
    failure: str | None = None
    runtime_s: float = 0.0
    compile_s: float = 0.0
    duration_s: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)
    imu_noise: dict[str, Any] = field(default_factory=dict)
    fix_noise: dict[str, Any] = field(default_factory=dict)
    obs_noise: dict[str, Any] = field(default_factory=dict)
    smoothed: tuple[F64, F64] | None = None
    smoothing: Smoothing | None = None

    def smoothed_run(self) -> RunResult | None:
        """This run with its smoothed states and covariances as its outputs (what the
        estimate table, the metrics and the error tracks read), or None if not smoothed."""
        if self.smoothed is None:
            return None
        x, P = self.smoothed
        return replace(self, x=x, P=P, smoothed=None)


@dataclass(frozen=True)
class Smoothing:
    """What the backward pass of a run cost and how it ended.

    Attributes:
        status: ``ok``; ``failed`` (a covariance of the backward pass not positive
            definite: the segment's outputs are left as the forward filter's), with
            ``failure``; ``not_run`` (no segment ran: the filter never aligned).
        runtime_s: the backward passes' wall time (not in the run's ``runtime_s``);
            compile_s: compiling or loading the backward pass (in the run's ``compile_s``);
            memory_bytes: what the forward pass kept for them (``records.SmoothLog``, as
            allocated; of the longest segment), beside the run's own outputs.
    """

    status: str = "ok"
    failure: str | None = None
    runtime_s: float = 0.0
    memory_bytes: int = 0
    compile_s: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "failure": self.failure,
            "runtime_s": self.runtime_s,
            "compile_s": self.compile_s,
            "memory_mb": self.memory_bytes / 1e6,
        }


def make_setup(
    name: str,
    params: InsFilterParams,
    sensors: SensorMeta | None,
    noise_model: ImuNoise | None = None,
    fix_error: tuple[float, float] = (0.0, 0.0),
) -> FilterSetup:
    """Pack the settings of filter ``name`` for the kernels (sensor metadata first).

    ``noise_model``: the IMU noise to use (``resolve_imu_noise``); default: the dataset's,
    else the params' fallback. ``fix_error``: (tau s, sigma m) of the Gauss-Markov fix-error
    states of a loosely coupled filter (``_fix_error_states``; tau 0: none), which take the
    tightly coupled clock's two states.
    """
    kind = FILTER_KINDS[name]
    n = ins.N_TIGHT if kind.coupling == "tight" or fix_error[0] > 0.0 else ins.N_LOOSE
    if noise_model is None:
        noise_model = (
            sensors.imu_noise if sensors is not None and sensors.imu_noise else params.imu_noise
        )
    lever = np.array(sensors.lever_arm_m if sensors is not None else (0.0, 0.0, 0.0), float)
    st, g = params.step, params.gating
    wm = wc = np.ones(1)
    gamma = 0.0
    ukf = (params.ukf.alpha, params.ukf.beta, params.ukf.kappa) if params.ukf else (0.0, 0.0, 0.0)
    if params.ukf is not None:
        wm, wc, gamma = ukf_weights(n, *ukf)
    noise = ins_errors.noise_vector(
        noise_model.accel_noise_mps2_rthz,
        noise_model.gyro_noise_radps_rthz,
        noise_model.accel_bias_rw_mps3_rthz,
        noise_model.gyro_bias_rw_radps2_rthz,
        params.clock.bias_psd_m2ps,
        params.clock.drift_psd_m2ps3,
        st.gap_accel_psd_m2ps3,
        st.gap_gyro_psd_rad2ps,
        fix_error,
        st.second_order_corr_s,
    )
    nhc = params.nhc
    nhc_sigma = np.array(
        [nhc.sigma_lateral_mps, nhc.sigma_vertical_mps] if nhc is not None else [1.0, 1.0]
    )
    gate = np.array([math.inf] + [chi2_ppf(g.probability, d) for d in (1, 2, 3)])
    fz = (
        params.fuzzy.vector() if kind.fading and params.fuzzy is not None
        else params.iae.vector() if kind.iae and params.iae is not None
        else None
    )  # fmt: skip
    settings = Settings(
        n=n,
        substeps=int(st.substeps),
        max_step_s=float(st.max_rk4_step_s),
        gap_s=float(st.imu_gap_s),
        nhc_on=bool(kind.nhc),
        timeout_s=float(g.timeout_s),
        return_gap_s=float(g.return_gap_s),
        return_epochs=int(g.return_epochs),
        reset_pos_sigma_m=float(g.reset_pos_sigma_m),
        reset_vel_sigma_mps=float(g.reset_vel_sigma_mps),
        reset_clock_sigma_m=float(g.reset_clock_sigma_m),
        max_pos_sigma_m=float(params.divergence.max_pos_sigma_m),
        max_speed_mps=float(params.divergence.max_speed_mps),
        ukf_gamma=float(gamma),
        ukf_alpha=float(ukf[0]),
        ukf_beta=float(ukf[1]),
        ukf_kappa=float(ukf[2]),
        noise=noise,
        lever_b=lever,
        nhc_sigma=nhc_sigma,
        still_on=bool(params.standstill.enabled),
        still_sigma=np.array(
            [
                params.standstill.vel_sigma_mps,
                params.standstill.rate_sigma_radps,
                params.standstill.max_speed_mps,
            ]
        ),
        gate=gate,
        wm=wm,
        wc=wc,
    )
    return FilterSetup(name, kind.estimator, settings, fz)


#: platforms whose quiet IMU may be a hover: at rest only on the ground (``standstill``)
AIRCRAFT = ("multirotor", "fixed_wing", "vtol")


def _standstill(
    imu: inp.ImuData,
    noise: ImuNoise,
    fixes: inp.FixData | None,
    params: InsFilterParams,
    sensors: SensorMeta | None,
) -> I64:
    """The standstill intervals of the run (``standstill.detect``; an aircraft's on the ground
    only), logged."""
    lat = h = 0.0
    if fixes is not None and fixes.usable.any():
        first = fixes.fix[np.flatnonzero(fixes.usable)[0]]
        lat, h = float(first[me.FX_LAT]), float(first[me.FX_ALT])
    kind = sensors.platform.kind if sensors is not None else "unknown"
    aircraft = kind in AIRCRAFT
    still = standstill.detect(
        imu, noise, fixes, params.standstill, params.init, lat, h, aircraft=aircraft
    )
    if still.size:
        total_s = float((still[:, 1] - still[:, 0]).sum()) * 1e-9
        log.info("standstill: %d interval(s), %.1f s in all (zero-velocity and angular-rate "
                 "updates)", len(still), total_s)  # fmt: skip
    return still


def _require(
    tables: Mapping[str, pa.Table],
    name: str,
    kind: FilterKind,
    fixes: inp.FixData | None,
    obs: inp.ObsData | None,
) -> None:
    """``ReplayInputError`` if the table the filter's coupling reads is absent or empty."""
    if kind.coupling == "loose" and fixes is None:
        _table(tables, "gnss", name)
    if kind.coupling == "tight" and obs is None:
        _table(tables, "gnss_obs", name)


def _table(tables: Mapping[str, pa.Table], name: str, filt: str) -> pa.Table:
    if name not in tables or tables[name].num_rows == 0:
        raise ReplayInputError(f"filter {filt} needs the {name!r} table, which is absent or empty")
    return tables[name]


KernelFn = Callable[..., int]


def _fix_error_states(kind: FilterKind, fixes: inp.FixData | None) -> tuple[float, float]:
    """(tau s, sigma m) of a loosely coupled run's Gauss-Markov fix-error states, (0, 0) if
    it inflates the fix variances instead (``inputs.prepare_fixes``)."""
    noise = fixes.noise if fixes is not None else None
    if kind.coupling != "loose" or noise is None or not noise.states:
        return 0.0, 0.0
    return noise.tau_s, noise.states_sigma_m


def with_fix_error_states(al: Alignment, fix_error: tuple[float, float]) -> Alignment:
    """A loosely coupled start (15 states) with the north and east fix errors (tau, 1-sigma:
    ``fix_error``; none for tau 0) appended as states 15 and 16: each of that 1-sigma, and
    exactly opposite to the position error the start took from a fix (``p0 = fix = p + e``,
    so ``dp = e = -dg``). The nominal slots they share with the tightly coupled clock start
    at zero either way: a fix's predicted north and east add them (``measurement.epoch_h``).
    A start that is not loosely coupled is returned as it is."""
    tau, sigma_m = fix_error
    if al.P0.shape[0] != ins.N_LOOSE:
        return al
    x0 = al.x0.copy()
    x0[ins.X_CB] = x0[ins.X_CD] = 0.0
    if tau <= 0.0:
        return replace(al, x0=x0)
    n = ins.N_TIGHT
    P0 = np.zeros((n, n))
    P0[: ins.N_LOOSE, : ins.N_LOOSE] = al.P0
    var = sigma_m * sigma_m
    for axis in range(2):
        g, p = ins.E_CB + axis, ins.E_POS + axis
        P0[g, g] = var
        P0[p, p] += var
        P0[p, g] = P0[g, p] = -var
    return replace(al, x0=x0, P0=P0)


def _adaptive_series(setup: FilterSetup, parts: list[F64]) -> dict[str, Any]:
    """The adaptive filters' series per output row: fwekf's fading factor ``alpha``, or
    iae_ekf's multiplier of the horizontal fix variance ``r_scale``."""
    if setup.adaptive is None or not parts:
        return {}
    key = "r_scale" if setup.adaptive[FZ_MODE] == MODE_IAE else "alpha"
    return {key: np.concatenate(parts)}


def kernel_for(kind: FilterKind, backend: Backend) -> KernelFn:
    """The function that runs a filter of ``kind`` on ``backend`` (a numba dispatcher for
    ``numba``)."""
    if backend == "numba":
        module, _, function = kind.numba_kernel.partition(":")
        kernel: KernelFn = getattr(importlib.import_module(module), function)
        return kernel
    if kind.adaptive:
        from navreplay.pipeline.estimation.ins.reference_fwekf import run_fwekf_filterpy

        return run_fwekf_filterpy
    from navreplay.pipeline.estimation.ins.reference import run_ekf_filterpy, run_ukf_filterpy

    return run_ekf_filterpy if kind.estimator == "ekf" else run_ukf_filterpy


def run_filter(
    tables: Mapping[str, pa.Table],
    sensors: SensorMeta | None,
    name: str,
    params: InsFilterParams,
    *,
    backend: Backend = "numba",
    imu: inp.ImuData | None = None,
    initial: Alignment | None = None,
    fix_noise: FixNoise | None = None,
    obs_noise: ObsNoise | None = None,
) -> RunResult:
    """Replay filter ``name`` over canonical tables (``imu`` + ``gnss`` or ``gnss_obs``).

    Args:
        tables: canonical tables by name (``truth`` is not read here).
        sensors: the dataset's sensor metadata (IMU noise, lever arm), or None.
        name: a key of ``config.FILTER_KINDS``.
        params: the filter's parameter section.
        backend: ``numba`` or ``filterpy``.
        imu: already cleaned IMU data (tests feeding raw arrays through ``inputs.clean_imu``);
            default: the ``imu`` table.
        initial: start the first segment from this state and covariance instead of aligning
            (a known initial condition; Monte Carlo consistency tests draw it from ``P0``).
        fix_noise: the fix-error model to use (``fixnoise.learn`` on the whole log, where
            ``tables`` are a scenario's or a window's part of it); default: learned here.
        obs_noise: the same for the pseudorange noise (``fixnoise.learn_obs``).

    Raises:
        ReplayInputError: a table the filter needs is missing.
        DivergenceError: the filter diverged and ``on_divergence`` is ``raise``.
    """
    t_wall = time.perf_counter()
    kind = FILTER_KINDS[name]
    kernel = kernel_for(kind, backend)
    imu_data = imu if imu is not None else inp.prepare_imu(_table(tables, "imu", name), params.step)
    noise_model, noise_source = resolve_imu_noise(params, sensors, imu_data)
    fixes = inp.prepare_fixes(tables["gnss"], params.gnss, fix_noise) if "gnss" in tables else None
    gm = _fix_error_states(kind, fixes)
    setup = make_setup(name, params, sensors, noise_model, gm)
    obs = (
        inp.prepare_obs(tables["gnss_obs"], params.gnss, obs_noise)
        if "gnss_obs" in tables
        else None
    )
    mag = inp.prepare_mag(tables["mag"]) if "mag" in tables else None
    _require(tables, name, kind, fixes, obs)
    events = list(imu_data.events)
    events += list(fixes.events) if fixes is not None and kind.coupling == "loose" else []
    events += list(obs.events) if obs is not None and kind.coupling == "tight" else []
    segment_runs: list[_Segment] = []
    alignments: list[Alignment] = []
    status, failure = "ok", None
    duration = 0.0
    meas = _measurements(kind.coupling, fixes, obs)
    course_is_heading = sensors is None or sensors.platform.kind in COURSE_IS_HEADING
    still = _standstill(imu_data, noise_model, fixes, params, sensors)
    for k_seg, seg in enumerate(imu_data.segments):
        al: Alignment | None = initial
        if initial is None or k_seg > 0:
            al = align(imu_data, seg, fixes, obs, params.init, noise_model, setup.lever_b,
                       ins.N_LOOSE if gm[0] > 0.0 else setup.n,  # the fix errors: below
                       course_is_heading=course_is_heading, mag=mag)  # fmt: skip
        if al is None:
            events.append(tb.Event(int(imu_data.t_ns[seg[0]]), "no_alignment", "imu"))
            continue
        al = with_fix_error_states(al, gm)
        alignments.append(al)
        run = _run_segment(kernel, setup, params, kind, imu_data, seg, meas, al, still)
        events += run.events
        segment_runs.append(run)
        out_t = run.out[0]
        duration += (out_t[-1] - al.t_ns) * 1e-9 if out_t.size else 0.0
        if run.code != gt.STATUS_OK:
            failure = f"{gt.STATUS_TEXT[run.code]} at t_ns={run.t_fail}"
            status = "diverged"
            if params.divergence.on_divergence == "raise":
                raise DivergenceError(
                    f"filter {name} ({backend}) diverged: {failure}; set "
                    f"filters.{name}.divergence.on_divergence: flag to keep the output up to it"
                )
            log.warning("filter %s diverged: %s", name, failure)
            break
    if not alignments and status == "ok":
        status = "not_aligned"
        failure = "the filter never aligned: " + why_not_aligned(
            fixes, obs, params.init, course_is_heading=course_is_heading
        )
        log.warning("filter %s: %s", name, failure)
    events.sort(key=lambda e: e.t_ns)
    parts = [r.out for r in segment_runs]
    smoothing = _smoothing(segment_runs) if params.smooth else Smoothing("off")
    compile_s = sum(r.compile_s for r in segment_runs)
    return RunResult(
        filter=name,
        backend=backend,
        n=setup.n,
        t_ns=np.concatenate([p[0] for p in parts]) if parts else np.empty(0, np.int64),
        x=np.concatenate([p[1] for p in parts]) if parts else np.empty((0, ins.FULL_DIM)),
        P=np.concatenate([p[2] for p in parts]) if parts else np.empty((0, setup.n, setup.n)),
        inn_i=np.concatenate([p[3] for p in parts]) if parts else np.empty((0, 5), np.int64),
        inn_f=np.concatenate([p[4] for p in parts]) if parts else np.empty((0, 8)),
        events=events,
        alignments=alignments,
        status=status,
        failure=failure,
        runtime_s=time.perf_counter()
        - t_wall
        - compile_s
        - smoothing.runtime_s
        - smoothing.compile_s,
        compile_s=compile_s + smoothing.compile_s,
        duration_s=duration,
        extra=_adaptive_series(setup, [r.alpha for r in segment_runs]),
        imu_noise={
            "source": noise_source,
            "accel_noise_mps2_rthz": noise_model.accel_noise_mps2_rthz,
            "gyro_noise_radps_rthz": noise_model.gyro_noise_radps_rthz,
        },
        fix_noise=(
            {**fixes.noise.as_dict(), **_latency(tables["gnss"], params.gnss, sensors)}
            if fixes is not None and fixes.noise is not None and kind.coupling == "loose"
            else {}
        ),
        obs_noise=(
            obs.noise.as_dict()
            if obs is not None and obs.noise is not None and kind.coupling == "tight"
            else {}
        ),
        smoothed=_smoothed(segment_runs) if params.smooth and segment_runs else None,
        smoothing=smoothing if params.smooth else None,
    )


def _smoothed(runs: list[_Segment]) -> tuple[F64, F64]:
    """The smoothed states and covariances of a run's segments, in order (a segment whose
    backward pass failed keeps its forward outputs)."""
    parts = [r.smoothed if r.smoothed is not None else (r.out[1], r.out[2]) for r in runs]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def _smoothing(runs: list[_Segment]) -> Smoothing:
    """A run's smoothing from its segments': failed if any failed, not run if none ran."""
    segments = [r.smoothing for r in runs if r.smoothing is not None]
    if not segments:
        return Smoothing("not_run", "no segment of the log was filtered (the filter never aligned)")
    failed = [s for s in segments if s.status != "ok"]
    return Smoothing(
        "failed" if failed else "ok",
        failed[0].failure if failed else None,
        sum(s.runtime_s for s in segments),
        max((s.memory_bytes for s in segments), default=0),
        sum(s.compile_s for s in segments),
    )


def _latency(table: pa.Table, gnss: GnssNoiseParams, sensors: SensorMeta | None) -> dict[str, Any]:
    """What ``metrics.json`` ``fix_noise`` says of the fixes' latency: the median applied and
    where it came from (nothing where none was applied)."""
    if not gnss.use_fix_latency or "latency_s" not in table.column_names:
        return {}
    latency = tb.float_column(table, "latency_s")
    if not np.isfinite(latency).any():
        return {}
    source = "the log's own per-fix latency"
    if sensors is not None and sensors.gnss_latency_s is not None:
        source = sensors.gnss_latency_source
    return {"latency_s": float(np.nanmedian(latency)), "latency_source": source}


def _typeof(value: object) -> Any:
    return nb.typeof(value)  # type: ignore[no-untyped-call]


def resolve_imu_noise(
    params: InsFilterParams, sensors: SensorMeta | None, imu: inp.ImuData
) -> tuple[ImuNoise, str]:
    """The IMU noise model of a run and where it came from.

    The dataset's model (``dataset.yaml`` ``imu.noise``) when it declares one:
    ``"dataset"``. Otherwise the params' MEMS fallback (``filters.<name>.imu_noise``), its
    white-noise densities floored by what the log shows (``inputs.imu_white_noise``):
    ``"params"``, or ``"params, floored by the log"`` when the log is noisier. A log of
    decimated, vibration-aliased samples fused with datasheet noise makes the filter
    overconfident in its own prediction until the gates lock the GNSS out.
    """
    if sensors is not None and sensors.imu_noise is not None:
        return sensors.imu_noise, "dataset"
    base = params.imu_noise
    acc, gyro = inp.imu_white_noise(imu)
    if acc <= base.accel_noise_mps2_rthz and gyro <= base.gyro_noise_radps_rthz:
        return base, "params"
    floored = replace(
        base,
        accel_noise_mps2_rthz=max(base.accel_noise_mps2_rthz, acc),
        gyro_noise_radps_rthz=max(base.gyro_noise_radps_rthz, gyro),
    )
    log.info(
        "no IMU noise model in the dataset: the log's samples are noisier than the fallback, "
        "using accel %.3g m/s^2/rtHz, gyro %.3g rad/s/rtHz (declare imu.noise in "
        "dataset.yaml to override)",
        floored.accel_noise_mps2_rthz,
        floored.gyro_noise_radps_rthz,
    )
    return floored, "params, floored by the log"


class _Measurements(NamedTuple):
    """A kernel's measurement tables (``models.measurement``) and their epoch times."""

    fix: F64
    fix_t: I64 | None
    obs: F64
    obs_start: I64
    obs_t: I64 | None


def _measurements(
    coupling: str, fixes: inp.FixData | None, obs: inp.ObsData | None
) -> _Measurements:
    """(fix rows, fix times, obs rows, obs epoch starts, obs epoch times) for a kernel.

    The table a filter does not read is passed empty, so loose and tight coupling share one
    compiled kernel (the measurement code skips a table whose epochs the schedule never
    names).
    """
    no_fix, no_obs = np.zeros((0, me.FIX_COLS)), np.zeros((0, me.OBS_COLS))
    if coupling == "loose":
        if fixes is None:
            return _Measurements(no_fix, None, no_obs, np.zeros(1, np.int64), None)
        fix_t = fixes.t_ns[fixes.usable]
        fix = np.ascontiguousarray(fixes.fix[fixes.usable])
        return _Measurements(fix, fix_t, no_obs, np.zeros(1, np.int64), None)
    if obs is None:
        return _Measurements(no_fix, None, no_obs, np.zeros(1, np.int64), None)
    return _Measurements(no_fix, None, np.ascontiguousarray(obs.obs), obs.start, obs.epoch_t_ns)


class _Segment(NamedTuple):
    """What one segment's run gave ``run_filter``."""

    out: tuple[I64, F64, F64, I64, F64]
    code: int
    t_fail: int
    events: list[tb.Event]
    compile_s: float
    alpha: F64
    smoothed: tuple[F64, F64] | None
    smoothing: Smoothing | None


def _run_segment(
    kernel: KernelFn,
    setup: FilterSetup,
    params: InsFilterParams,
    kind: FilterKind,
    imu: inp.ImuData,
    seg: tuple[int, int],
    meas: _Measurements,
    al: Alignment,
    still: I64,
) -> _Segment:
    """Run ``kernel`` over the IMU samples ``seg`` of ``imu`` from the alignment ``al``
    (``still``: the standstill intervals, ``standstill.detect``), and its backward pass if the
    params say ``smooth``."""
    lo, hi = seg
    imu_t = imu.t_ns[lo:hi]
    imu_d = imu.data[lo:hi]
    t_end = int(imu_t[-1])
    fix_arr, fix_t, obs_arr, obs_start, obs_t = meas
    nhc_rate = params.nhc.rate_hz if kind.nhc and params.nhc is not None else None
    stops = inp.build_schedule(al.t_ns, t_end, params.step.step_s, fix_t, obs_t, nhc_rate)
    stops[:, me.ST_STILL] = standstill.flag_stops(stops[:, me.ST_T], al.t_ns, still)
    m_max = inp.max_rows(stops, obs_start, kind.coupling == "tight")
    i0, u0 = inp.interpolate_input(imu_t, imu_d, al.t_ns)
    n = setup.n
    n_out = int(stops[:, me.ST_OUT].sum()) + 1
    n_inn = len(stops) * m_max
    n_ev = n_inn + 2 * len(stops) + 16
    sched = Schedule(int(al.t_ns), int(i0), u0, imu_t, imu_d, stops, obs_start, int(m_max))

    def kernel_args(log_: RunLog, sm: SmoothLog) -> tuple[tuple[object, ...], F64]:
        """The kernel's arguments writing into ``log_`` and ``sm``, and fwekf's alpha per
        output row."""
        out_alpha = np.ones(log_.capacity()[0])
        args: tuple[object, ...] = (al.x0, al.P0, sched, fix_arr, obs_arr, setup.settings)
        if setup.adaptive is not None:
            from navreplay.pipeline.estimation.ins.fuzzy import RULES

            args = (*args, Fading(setup.adaptive, RULES, out_alpha))
        return (*args, log_, sm), out_alpha

    first = RunLog.allocate(n_out, n_inn, n_ev, n, ins.FULL_DIM)
    sm = _smooth_log(params.smooth, kind, stops, n_out, n)
    compile_s = 0.0
    if hasattr(kernel, "compile"):  # a numba dispatcher: compile or load it outside the timing
        t0 = time.perf_counter()
        with fewer_gc_passes():
            kernel.compile(tuple(_typeof(a) for a in kernel_args(first, sm)[0]))
        compile_s = time.perf_counter() - t0
    log_ = first
    while True:
        args, out_alpha = kernel_args(log_, sm)
        code = kernel(*args)
        bigger, bigger_sm = log_.grown(), sm_kernel.grown(sm)
        if bigger is None and bigger_sm is None:
            break
        log.info("run log full (%s wanted, %s held): growing it", log_.wanted(), log_.capacity())
        log_ = bigger if bigger is not None else RunLog.allocate(*log_.capacity(), n, ins.FULL_DIM)
        sm = bigger_sm if bigger_sm is not None else sm_kernel.empty_like(sm)
    out_t, out_x, out_P, inn_i, inn_f, ev_i, ev_f, counts = log_
    k_out, k_inn, k_ev = log_.wanted()
    seg_events = [
        tb.Event(
            int(ev_i[j, 0]),
            gt.EVENT_NAMES.get(int(ev_i[j, 1]), str(ev_i[j, 1])),
            me.STREAM_NAMES[ev_i[j, 2]] if ev_i[j, 2] >= 0 else "",
            me.sv_name(int(ev_i[j, 3])),
            float(ev_f[j]),
        )
        for j in range(k_ev)
    ]
    out = (out_t[:k_out], out_x[:k_out], out_P[:k_out], inn_i[:k_inn], inn_f[:k_inn])
    smoothed, smoothing = None, None
    if sm_kernel.sm_on(sm):
        backward = sm_kernel.smooth if hasattr(kernel, "compile") else _smooth_filterpy()
        smoothed, smoothing = _backward(backward, sm, out[1], out[2], setup.settings)
    return _Segment(
        out, int(code), int(counts[rl.CNT_T_FAIL]), seg_events, compile_s, out_alpha[:k_out],
        smoothed, smoothing,
    )  # fmt: skip


def _smooth_log(smooth: bool, kind: FilterKind, stops: I64, n_out: int, n: int) -> SmoothLog:
    """The smoothing log of a run over ``stops``, ``n_out`` of them outputs (the start
    included), sized for what its estimator pools (``records.SmoothLog``): the UKF a cross
    covariance per stop and a prior per update epoch, the EKFs the posteriors between output
    times (and fwekf its faded priors); no rows if the run is not smoothed. A pool found too
    small is grown (``smoother.grown``)."""
    if not smooth:
        return sm_kernel.allocate(0, 0, n)
    n_stops = len(stops)
    between = n_stops + 1 - n_out
    updates = int(
        ((stops[:, me.ST_FIX] >= 0) | (stops[:, me.ST_OBS] >= 0) | (stops[:, me.ST_NHC] > 0)
         | (stops[:, me.ST_STILL] > 0)).sum()
    )  # fmt: skip
    ukf = kind.estimator == "ukf"
    pool = (
        n_stops + updates + between if ukf
        else updates + between if kind.adaptive
        else between + 16
    )  # fmt: skip
    return sm_kernel.allocate(n_stops + 1, pool, n, nominal=not ukf)


def _smooth_filterpy() -> KernelFn:
    from navreplay.pipeline.estimation.ins.reference_smoother import smooth_filterpy

    return smooth_filterpy


def _backward(
    backward: KernelFn, sm: SmoothLog, out_x: F64, out_P: F64, cfg: Settings
) -> tuple[tuple[F64, F64] | None, Smoothing]:
    """The backward pass (``smoother.smooth``, or filterpy's for the reference backend) over a
    segment's smoothing log: its smoothed outputs (None if it failed) and how it went."""
    xs, Ps = out_x.copy(), out_P.copy()
    args = (sm, out_x, out_P, cfg, xs, Ps)
    compile_s = 0.0
    if hasattr(backward, "compile"):  # compile or load it outside the timing, as the kernel
        t0 = time.perf_counter()
        with fewer_gc_passes():
            backward.compile(tuple(_typeof(a) for a in args))
        compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    code = backward(*args)
    memory = sum(a.nbytes for a in sm)
    runtime = time.perf_counter() - t0
    if code != sm_kernel.SMOOTH_OK:
        failure = f"the backward pass stopped: {sm_kernel.SMOOTH_FAILURES[int(code)]}"
        log.warning("smoothing failed: %s; the segment keeps the forward estimate", failure)
        return None, Smoothing("failed", failure, runtime, memory, compile_s)
    return (xs, Ps), Smoothing("ok", None, runtime, memory, compile_s)
