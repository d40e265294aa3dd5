"""The integrity monitor: does a finished run still agree with its own measurements?

A filter can finish without a NaN or a limit crossed and still be wrong: aligned on a wrong
heading, or with a bias prior too tight, its estimate drifts away from the measurements, which
the gate then rejects one after the other, and nothing in the run says so. The monitor reads
what every family writes, the innovations table (one row per gated measurement block, with
its NIS, dimension and whether it was accepted), and gives the run a status:

- ``diverged``: the estimate has left the measurements. Over a sliding window the median NIS
  per degree of freedom of a stream exceeds ``diverged_nis`` (the typical measurement lies
  ``sqrt(diverged_nis)`` sigma away, 5 sigma by default), accepted or not, for at least
  ``diverged_s``. The median ignores isolated outliers (a burst of bad fixes that the gate
  rejects is not a divergence).
- ``inconsistent``: the innovations are larger than the filter's own covariance says. A
  window fails when the sum of its NIS exceeds the chi-square bound at size ``alpha`` for its
  degrees of freedom *and* its mean NIS per dof exceeds ``nis_factor`` (a chi-square test over
  hundreds of samples detects misfits of a few per cent, which are no reason to distrust a
  run). Innovations correlated in time (a fix error that drifts slowly) make fewer
  independent samples than rows: the degrees of freedom are scaled by the effective-sample
  factor ``(1 - rho^2) / (1 + rho^2)`` of the stream's lag-1 autocorrelation ``rho`` of the
  normalized innovations (the variance of a sum of squares of an AR(1) sequence). The run is
  inconsistent when more than ``fail_fraction`` of a stream's windows fail.

The ``standstill`` stream (an INS filter's zero-velocity and zero-rate updates) does not
make a run diverged: its misfit says the vehicle was taken for at rest when it was not (a
hover in a simulator without vibration), which the gate handles, not that the estimate left
the sensors; it still counts towards ``inconsistent``.

Rejected blocks count: a filter that rejects everything has, by construction, no accepted
innovation that disagrees with it. The monitor runs on every family's output (``contract.
RunOutput.decode``); its verdict only ever lowers a run's status (a run the kernel already
ended as ``diverged`` or ``not_aligned`` keeps that status).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.pipeline.distributions import chi2_isf
from navreplay.pipeline.estimation.core.checks import positive
from navreplay.pipeline.estimation.core.windows import NS

#: The statuses of a run, from good to bad.
STATUSES = ("ok", "inconsistent", "diverged", "not_aligned")
#: Statuses of a run that finished with an estimate over the whole log, to be read with care
#: when not ``ok``: accuracy tables keep them and show the status beside them.
FINISHED = ("ok", "inconsistent")


@dataclass(frozen=True)
class IntegrityParams:
    """The monitor's tests (see the module docstring).

    Attributes:
        window_s: length of the sliding window, s (windows start every ``window_s / 2``).
        min_blocks: a window with fewer measurement blocks of a stream is not tested.
        alpha: size of each window's chi-square test.
        nis_factor: a window fails only if its mean NIS per dof also exceeds this.
        fail_fraction: the run is inconsistent when more windows of a stream than this
            fraction fail.
        diverged_nis: median NIS per dof above which a window's measurements have been left
            behind.
        diverged_s: ... for at least this long: the run diverged.
    """

    window_s: float = 10.0
    min_blocks: int = 5
    alpha: float = 1e-3
    nis_factor: float = 2.0
    fail_fraction: float = 0.1
    diverged_nis: float = 25.0
    diverged_s: float = 10.0

    def __post_init__(self) -> None:
        positive(self, "window_s", "alpha", "nis_factor", "diverged_nis", "diverged_s")


@dataclass(frozen=True)
class StreamIntegrity:
    """One stream's tests.

    Attributes:
        windows, failed: windows tested and windows failing the consistency test.
        rho: lag-1 autocorrelation of the normalized innovations (clipped to [0, 0.95]).
        worst_nis: largest windowed mean NIS per dof, and the start of that window, ns.
        diverged_ns: start of the first run of windows beyond ``diverged_nis`` that lasted
            ``diverged_s``, or None.
    """

    windows: int
    failed: int
    rho: float
    worst_nis: float
    worst_ns: int
    diverged_ns: int | None

    def to_json(self) -> dict[str, Any]:
        return {
            "windows": self.windows,
            "failed": self.failed,
            "rho": round(self.rho, 4),
            "worst_nis_per_dof": round(self.worst_nis, 4),
            "worst_t_ns": self.worst_ns,
            "diverged_t_ns": self.diverged_ns,
        }


@dataclass(frozen=True)
class Integrity:
    """The monitor's verdict: ``status`` (``ok``, ``inconsistent`` or ``diverged``), from
    ``t_ns`` on, ``reason`` in words, and the tests per stream."""

    status: str
    t_ns: int | None
    reason: str | None
    streams: dict[str, StreamIntegrity] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "t_ns": self.t_ns,
            "reason": self.reason,
            "streams": {k: v.to_json() for k, v in self.streams.items()},
        }


def _rho(t: np.ndarray, z: np.ndarray, window_s: float) -> float:
    """Lag-1 autocorrelation of consecutive normalized innovations (pairs further apart
    than half a window are not neighbours), averaged over the components."""
    near = np.diff(t) < window_s * NS / 2
    rhos = []
    for k in range(z.shape[1]):
        a, b = z[:-1, k], z[1:, k]
        ok = near & np.isfinite(a) & np.isfinite(b)
        if ok.sum() > 10 and np.std(a[ok]) > 0 and np.std(b[ok]) > 0:
            rhos.append(float(np.corrcoef(a[ok], b[ok])[0, 1]))
    return float(np.clip(np.mean(rhos), 0.0, 0.95)) if rhos else 0.0


def _stream(
    t: np.ndarray, nis: np.ndarray, dim: np.ndarray, z: np.ndarray, p: IntegrityParams
) -> StreamIntegrity:
    rho = _rho(t, z, p.window_s)
    scale = (1.0 - rho**2) / (1.0 + rho**2)
    win, step = round(p.window_s * NS), round(p.window_s * NS / 2)
    starts = np.arange(int(t[0]), int(t[-1]) - win + step + 1, step, dtype=np.int64)
    lo = np.searchsorted(t, starts)
    hi = np.searchsorted(t, starts + win)
    cs_nis = np.concatenate([[0.0], np.cumsum(nis)])
    cs_dim = np.concatenate([[0.0], np.cumsum(dim)])
    windows = failed = 0
    worst, worst_ns = 0.0, int(t[0])
    run_from: int | None = None
    diverged: int | None = None
    for a, i, j in zip(starts, lo, hi, strict=True):
        if j - i < p.min_blocks:
            run_from = None
            continue
        windows += 1
        s, d = cs_nis[j] - cs_nis[i], cs_dim[j] - cs_dim[i]
        if s / d > worst:
            worst, worst_ns = s / d, int(a)
        if s / d > p.nis_factor and scale * s > chi2_isf(p.alpha, scale * d):
            failed += 1
        if np.median(nis[i:j] / dim[i:j]) > p.diverged_nis:
            run_from = int(a) if run_from is None else run_from
            if diverged is None and a + win - run_from >= p.diverged_s * NS:
                diverged = run_from
        else:
            run_from = None
    return StreamIntegrity(windows, failed, rho, worst, worst_ns, diverged)


def assess(innovations: pa.Table, p: IntegrityParams, t0_ns: int | None = None) -> Integrity:
    """The monitor's verdict on a run's innovations table (see the module docstring);
    times in the reasons count from ``t0_ns`` (default: the first innovation)."""
    if innovations.num_rows == 0:
        return Integrity("ok", None, None)
    t_all = innovations.column("t_ns").to_numpy()
    t0 = int(t_all.min()) if t0_ns is None else t0_ns
    streams: dict[str, StreamIntegrity] = {}
    names = innovations.column("stream").to_numpy(zero_copy_only=False)
    nis_all = innovations.column("nis").to_numpy(zero_copy_only=False).astype(float)
    dim_all = innovations.column("dim").to_numpy().astype(float)
    comps = [c for c in innovations.column_names if c.startswith("innov_") and "sigma" not in c]
    z_all = np.column_stack(
        [
            innovations.column(c).to_numpy(zero_copy_only=False).astype(float)
            / innovations.column(c.replace("innov_", "innov_sigma_"))
            .to_numpy(zero_copy_only=False)
            .astype(float)
            for c in comps
        ]
    )
    for name in sorted(set(names)):
        rows = (names == name) & np.isfinite(nis_all) & (dim_all > 0)
        if rows.sum() < p.min_blocks:
            continue
        order = np.argsort(t_all[rows], kind="stable")
        streams[str(name)] = _stream(
            t_all[rows][order], nis_all[rows][order], dim_all[rows][order], z_all[rows][order], p
        )
    return _verdict(streams, p, t0)


#: pseudo-measurements of an assumed condition, not of a sensor: never ``diverged``
ASSUMED = frozenset({"standstill"})


def _verdict(streams: dict[str, StreamIntegrity], p: IntegrityParams, t0: int) -> Integrity:
    diverged = [
        (s.diverged_ns, k)
        for k, s in streams.items()
        if s.diverged_ns is not None and k not in ASSUMED
    ]
    if diverged:
        at, name = min(diverged)
        return Integrity(
            "diverged",
            at,
            f"the estimate left the {name} measurements {(at - t0) / NS:.1f} s after the first "
            "measurement: for "
            f"{p.diverged_s:g} s or more their median NIS per dof exceeded {p.diverged_nis:g} "
            f"(they lay over {p.diverged_nis**0.5:.0f} sigma away, accepted or not)",
            streams,
        )
    bad = [
        (s.failed / s.windows, k)
        for k, s in streams.items()
        if s.windows and s.failed / s.windows > p.fail_fraction
    ]
    if bad:
        _, name = max(bad)
        s = streams[name]
        return Integrity(
            "inconsistent",
            s.worst_ns,
            f"the {name} innovations are larger than the filter's covariance says: {s.failed} "
            f"of {s.windows} windows of {p.window_s:g} s fail the chi-square test at "
            f"{p.alpha:g} with a mean NIS per dof above {p.nis_factor:g} (worst "
            f"{s.worst_nis:.1f}, {(s.worst_ns - t0) / NS:.1f} s after the first measurement)",
            streams,
        )
    return Integrity("ok", None, None, streams)
