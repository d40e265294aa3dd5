"""The receiver's fix errors learned from the log: their correlation time, and their size
where the receiver reports none.

Each axis of a fix error is taken as a first-order Gauss-Markov process of variance sigma^2
and correlation time tau. The receiver's velocity (Doppler, tracked independently of the
position solution) carries none of it, so over ``L`` fix intervals the position change minus
the integrated velocity,

    d_k(L) = (p_{k+L} - p_k) - integral of v dt   (trapezoid over the fixes),

is the change of the error plus the integrated velocity noise. Its variance, the structure
function of the error,

    D(L) = 2 sigma^2 (1 - exp(-L dt / tau)) + q L dt,

is flat from the first lag on for white errors and rises over tau for correlated ones; ``q``
absorbs the velocity noise and the trapezoid's own error. For each tau of a grid, ``2 sigma^2``
and ``q`` follow from a non-negative least-squares fit over log-spaced lags (relative
residuals, each lag weighted by how many differences it has); the tau that fits best wins.

What the filters take from it (``inputs.prepare_fixes``): tau sets how much of each fix is
new information, the variance inflation ``(1 + phi) / (1 - phi)`` with ``phi = exp(-dt/tau)``
(``~1 + 2 tau/dt``; 1 for white errors: the variance of the mean of correlated samples);
sigma replaces the default where the receiver reports no accuracy. Without a receiver
velocity the motion and the error cannot be told apart from the fixes alone, and the
configured ``pos_error_corr_time_s`` and ``pos_sigma_default_m`` are used. Where such a
receiver reports its accuracy, the fixes' third differences still tell white errors from
correlated ones (``_white_sigma``): motion leaves little in them (a car's jerk at 1 Hz is
under a metre), white errors of sigma give sqrt(20) sigma, errors correlated over tens of
seconds almost nothing. Errors white at the reported size are taken as white (no inflation);
errors of which under half the reported size changes from fix to fix are said to be
correlated, and keep the configured inflation: they do not become Gauss-Markov states of an
assumed tau (on a robot creeping at 1 m/s that left the yaw 17-22 deg off at a 2.3-2.8 deg
sigma). The run's ``metrics.json`` says which (``fix_noise``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import nnls

from navreplay.ingest.gnss import spp
from navreplay.pipeline.estimation.ins.config import GnssNoiseParams
from navreplay.pipeline.estimation.ins.models import measurement as me
from navreplay.pipeline.nav import earth
from navreplay.pipeline.nav.earth import F64, I64

#: at least this many consecutive fix pairs with velocity ...
MIN_PAIRS = 100
#: ... spanning at least this long in one run of fixes, s
MIN_SPAN_S = 60.0
#: without a receiver velocity, the fixes' third differences show their white part: at least
#: this share of the reported variance is white errors ...
WHITE_SHARE_MIN = 0.5
#: ... at most this share, correlated ones
CORRELATED_SHARE_MAX = 0.25
#: the longest lag used, s (and a third of the longest run of fixes)
MAX_LAG_S = 600.0
#: lags tried (log-spaced, in fix intervals)
N_LAGS = 24
#: correlation times tried, s (0: white)
TAU_GRID_S = np.concatenate([[0.0], np.geomspace(0.2, 2000.0, 81)])
#: the fit's tolerance for the longest tau it still accepts (besides twice the best misfit)
DELTA_CHI2 = 1.0
#: a run of fixes breaks where the interval exceeds this many median intervals (at 1 Hz), ...
GAP_FACTOR = 1.5
#: ... or this long at faster rates (a dropped fix or two at 5-10 Hz is bridged), s
GAP_BRIDGE_S = 0.6


@dataclass(frozen=True)
class FixNoise:
    """The fix-error model a run used, and where it came from.

    Attributes:
        tau_s: correlation time of the position errors, s (0: white).
        inflation: fix variance inflation for that correlation, ``(1 + phi)/(1 - phi)``.
        source: ``learned`` (from the fixes and the receiver velocity) or ``configured``.
        reason: why, in words.
        sigma_h_m: per-axis horizontal 1-sigma learned from the log, m (NaN if not learned).
        sigma_v_m: vertical 1-sigma learned from the log, m (NaN if not learned).
        sigma_source: ``reported`` (the receiver's accuracies), ``learned`` or ``default``.
        reported_h_m: median reported horizontal accuracy, m (NaN if none).
        pairs: fix pairs the fit used.
        states: the north and east errors are Gauss-Markov states of the filter
            (``GnssNoiseParams.fix_error_states``) rather than an inflation.
        states_sigma_m: their 1-sigma, m (the fixes' median horizontal sigma; NaN if none).
        correlated: without a receiver velocity, the fixes' third differences showed their
            errors correlated (the configured tau and its inflation are kept).
    """

    tau_s: float
    inflation: float
    source: str
    reason: str
    sigma_h_m: float = math.nan
    sigma_v_m: float = math.nan
    sigma_source: str = "default"
    reported_h_m: float = math.nan
    pairs: int = 0
    states: bool = False
    states_sigma_m: float = math.nan
    correlated: bool = False

    def as_dict(self) -> dict[str, object]:
        """JSON-ready (NaN as None)."""
        return {k: (None if isinstance(v, float) and math.isnan(v) else v)
                for k, v in asdict(self).items()}  # fmt: skip


def inflation(tau_s: float, dt_s: float) -> float:
    """Variance inflation of a fix whose error is Gauss-Markov with ``tau_s``, sampled every
    ``dt_s``: ``(1 + phi) / (1 - phi)``, ``phi = exp(-dt/tau)`` (1 when white)."""
    if tau_s <= 0.0 or dt_s <= 0.0:
        return 1.0
    return 1.0 / math.tanh(dt_s / (2.0 * tau_s))


def structure(tau_s: float, lag_s: F64) -> F64:
    """``1 - exp(-lag/tau)``: the Gauss-Markov part of ``D`` per ``2 sigma^2`` (1 if white)."""
    if tau_s <= 0.0:
        return np.ones_like(lag_s)
    return -np.expm1(-lag_s / tau_s)


def fit(lag_s: F64, d_var: F64, n_eff: F64) -> tuple[float, float, float]:
    """(tau, 2 sigma^2, q) of ``D(L) = 2 sigma^2 (1 - exp(-L/tau)) + q L`` fitting the observed
    variances ``d_var`` at ``lag_s``, each estimated from about ``n_eff`` independent
    differences (relative error ``sqrt(2 / n_eff)``).

    The longest tau whose misfit is at most twice the best one's (plus ``DELTA_CHI2``) is
    taken: a log holds few independent samples of a long correlation and the lags share
    their differences, so the misfit is flat over a wide range of tau; taking it too short
    makes the filter overconfident, too long only slower to follow the fixes.
    """
    w = np.sqrt(n_eff / 2.0) / d_var
    fits = []
    for tau in TAU_GRID_S:
        a = np.column_stack([structure(float(tau), lag_s), lag_s]) * w[:, None]
        coef, res = nnls(a, d_var * w)
        fits.append((float(res) ** 2, float(tau), float(coef[0]), float(coef[1])))
    best = min(f[0] for f in fits)
    _, tau, two_s2, q = max(
        (f for f in fits if f[0] <= 2.0 * best + DELTA_CHI2), key=lambda f: f[1]
    )
    return tau, two_s2, q


def _runs(t_ns: I64, ok: np.ndarray, dt_s: float) -> list[np.ndarray]:
    """Index runs of usable fixes without a gap."""
    idx = np.flatnonzero(ok)
    if idx.size < 2:
        return []
    limit = max(GAP_FACTOR * dt_s, min(3.0 * dt_s, GAP_BRIDGE_S))
    cut = np.flatnonzero(np.diff(t_ns[idx]) * 1e-9 > limit) + 1
    return [r for r in np.split(idx, cut) if r.size >= 2]


def _robust_var(x: F64) -> float:
    """Variance of ``x`` without its outliers (beyond 5 MAD-sigma): fix jumps and glitches
    must not pass for correlation."""
    dev = np.abs(x - np.median(x))
    scale = 1.4826 * float(np.median(dev))
    kept = x[dev <= 5.0 * scale] if scale > 0.0 else x
    return float(np.var(kept))


def _differences(t_ns: I64, pos: F64, vel: F64, runs: list[np.ndarray], lag: int) -> list[F64]:
    """``d_k(lag)`` per column of ``pos`` (local metres) against the integrated ``vel``."""
    out = []
    for r in runs:
        if r.size <= lag:
            continue
        t = t_ns[r] * 1e-9
        v = vel[r]
        step = 0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None]
        integ = np.vstack([np.zeros((1, v.shape[1])), np.cumsum(step, axis=0)])
        p = pos[r]
        out.append((p[lag:] - p[:-lag]) - (integ[lag:] - integ[:-lag]))
    return out


def _structure_function(
    t_ns: I64, pos: F64, vel: F64, runs: list[np.ndarray], dt_s: float, span_s: float
) -> tuple[F64, F64, F64]:
    """(lag s, pooled variance per axis, independent differences) over log-spaced lags."""
    max_lag = max(1, int(min(MAX_LAG_S, span_s / 3.0) / dt_s))
    lags = np.unique(np.round(np.geomspace(1, max_lag, N_LAGS)).astype(int))
    lag_s, d_var, count = [], [], []
    for lag in lags:
        parts = _differences(t_ns, pos, vel, runs, int(lag))
        if not parts:
            continue
        d = np.vstack(parts)
        if d.shape[0] < 20:
            continue
        lag_s.append(lag * dt_s)
        d_var.append(np.mean([_robust_var(d[:, j]) for j in range(d.shape[1])]))
        count.append(d.shape[0] * d.shape[1] / lag)  # overlapping differences: ~1 per lag
    return np.array(lag_s), np.array(d_var), np.array(count, float)


def _local(fix: F64, ok: np.ndarray) -> F64:
    """Fix positions as local north, east, down metres about the first usable one."""
    lat, lon, alt = fix[:, me.FX_LAT], fix[:, me.FX_LON], fix[:, me.FX_ALT]
    k = int(np.argmax(ok))
    rn, re = earth.radii(float(lat[k]))
    return np.column_stack(
        [(lat - lat[k]) * (rn + alt[k]), (lon - lon[k]) * (re + alt[k]) * math.cos(lat[k]),
         -(alt - alt[k])]
    )  # fmt: skip


def configured(gnss: GnssNoiseParams, dt_s: float, reason: str, reported_h: float) -> FixNoise:
    """The configured correlation time (``pos_error_corr_time_s``), and why."""
    tau = gnss.pos_error_corr_time_s
    sig = "reported" if math.isfinite(reported_h) else "default"
    return FixNoise(tau, inflation(tau, dt_s), "configured", reason, sigma_source=sig,
                    reported_h_m=reported_h)  # fmt: skip


def _without_velocity(
    t_ns: I64, fix: F64, gnss: GnssNoiseParams, dt: float, why: str, rep: float
) -> FixNoise:
    """The configured model, unless the fixes' third differences show their errors white at
    the receiver's reported accuracy ``rep``, or mostly correlated (see the module)."""
    base = configured(gnss, dt, why, rep)
    if not (math.isfinite(rep) and rep > 0.0 and gnss.learn_fix_noise):
        return base
    sigma_w, count = _white_sigma(t_ns, fix, dt)
    if count < MIN_PAIRS:
        return base
    share = (sigma_w / rep) ** 2
    seen = (f"{why}; their third differences show {sigma_w:.2f} m of white error against "
            f"the {rep:.2f} m reported ({count} differences)")  # fmt: skip
    if share >= WHITE_SHARE_MIN:
        return FixNoise(0.0, 1.0, "learned", f"{seen}: white", sigma_source="reported",
                        reported_h_m=rep, pairs=count)  # fmt: skip
    if share <= CORRELATED_SHARE_MAX:
        return FixNoise(base.tau_s, base.inflation, "configured",
                        f"{seen}: correlated, {base.tau_s:g} s taken", sigma_source="reported",
                        reported_h_m=rep, pairs=count, correlated=True)  # fmt: skip
    return FixNoise(base.tau_s, base.inflation, "configured", f"{seen}: undecided, "
                    f"{base.tau_s:g} s taken", sigma_source="reported", reported_h_m=rep,
                    pairs=count)  # fmt: skip


def _white_sigma(t_ns: I64, fix: F64, dt: float) -> tuple[float, int]:
    """(per-axis 1-sigma of the fixes' white errors, number of third differences): the
    robust variance of the horizontal third differences of evenly spaced fixes over 20."""
    ok = fix[:, me.FX_POS_DIM] >= 2
    if ok.sum() < 4:
        return math.nan, 0
    pos = _local(fix, ok)[:, :2]
    parts = []
    for r in _runs(t_ns, ok, dt):
        if r.size < 4:
            continue
        gaps = np.diff(t_ns[r]) * 1e-9
        even = np.abs(gaps - dt) <= 0.1 * dt
        keep = even[:-2] & even[1:-1] & even[2:]
        parts.append(np.diff(pos[r], n=3, axis=0)[keep])
    d3 = np.concatenate(parts) if parts else np.zeros((0, 2))
    if d3.shape[0] == 0:
        return math.nan, 0
    return math.sqrt(_robust_var(d3.ravel()) / 20.0), int(d3.shape[0])


def _unusable(t_ns: I64, fix: F64, gnss: GnssNoiseParams) -> str:
    """Why the fixes cannot teach their error model ("" if they can)."""
    if t_ns.size < 2:
        return "too few fixes to learn their errors from"
    if not gnss.learn_fix_noise:
        return "gnss.learn_fix_noise is off"
    if not np.any((fix[:, me.FX_POS_DIM] >= 2) & (fix[:, me.FX_VEL_DIM] >= 2)):
        return "no receiver velocity: the fixes alone cannot tell their errors from the motion"
    return ""


def _vertical_sigma(t_ns: I64, fix: F64, pos: F64, tau: float, dt: float, span: float) -> float:
    """The vertical 1-sigma for the horizontal ``tau`` (NaN without enough 3-D fixes)."""
    vert = (fix[:, me.FX_POS_DIM] == 3) & (fix[:, me.FX_VEL_DIM] == 3)
    runs = _runs(t_ns, vert, dt)
    if sum(r.size - 1 for r in runs) < MIN_PAIRS:
        return math.nan
    vel = fix[:, me.FX_VN + 2 : me.FX_VN + 3]
    lag, d_var, n_eff = _structure_function(t_ns, pos[:, 2:], vel, runs, dt, span)
    if lag.size < 4 or not np.all(d_var > 0.0):
        return math.nan
    w = np.sqrt(n_eff / 2.0) / d_var
    a = np.column_stack([structure(tau, lag), lag]) * w[:, None]
    return math.sqrt(float(nnls(a, d_var * w)[0][0]) / 2.0)


def learn(t_ns: I64, fix: F64, reported_h: F64, gnss: GnssNoiseParams) -> FixNoise:
    """The fix-error model of a log (see the module): learned from its fixes and receiver
    velocity where there are enough of both, else the configured one with the reason.

    ``fix``: rows of the ``fix`` layout (``FX_POS_DIM``, ``FX_VEL_DIM`` mark usable blocks);
    ``reported_h``: the receiver's per-fix horizontal accuracy, NaN where absent.
    """
    finite_rep = reported_h[np.isfinite(reported_h)]
    rep = float(np.median(finite_rep)) if finite_rep.size else math.nan
    dt = float(np.median(np.diff(t_ns))) * 1e-9 if t_ns.size > 1 else 1.0
    why = _unusable(t_ns, fix, gnss)
    ok = (fix[:, me.FX_POS_DIM] >= 2) & (fix[:, me.FX_VEL_DIM] >= 2)
    runs = _runs(t_ns, ok, dt) if not why else []
    pairs = sum(r.size - 1 for r in runs)
    span = max(((t_ns[r[-1]] - t_ns[r[0]]) * 1e-9 for r in runs), default=0.0)
    if not why and (pairs < MIN_PAIRS or span < MIN_SPAN_S):
        why = (f"{pairs} consecutive fixes with velocity over at most {span:.0f} s: too few to "
               f"learn from (>= {MIN_PAIRS} over {MIN_SPAN_S:.0f} s)")  # fmt: skip
    if why:
        return _without_velocity(t_ns, fix, gnss, dt, why, rep)
    pos = _local(fix, ok)
    vel = fix[:, me.FX_VN : me.FX_VN + 2]
    lag_s, d_h, count = _structure_function(t_ns, pos[:, :2], vel, runs, dt, span)
    if lag_s.size < 4 or not np.all(d_h > 0.0):
        return configured(gnss, dt, "the fixes' differences resolved no error model", rep)
    tau, two_s2, _ = fit(lag_s, d_h, count)
    sig = "reported" if math.isfinite(rep) else "learned"
    if tau > lag_s[-1]:  # not resolved: at least the longest lag
        tau = max(float(lag_s[-1]), gnss.pos_error_corr_time_s)
        # the variance the longest lag shows is 2 sigma^2 (1 - exp(-L / tau)) for the tau taken
        two_s2 = float(d_h[-1]) / float(structure(tau, lag_s[-1:])[0])
        how = (f"correlated beyond the longest lag the log allows ({lag_s[-1]:.0f} s): "
               f"{tau:.0f} s taken")  # fmt: skip
    else:
        how = "white at the fix rate" if tau < dt else f"correlated over {tau:.1f} s"
    return FixNoise(
        tau, inflation(tau, dt), "learned",
        f"fix errors {how} (position against the integrated receiver velocity, {pairs} pairs)",
        math.sqrt(two_s2 / 2.0), _vertical_sigma(t_ns, fix, pos, tau, dt, span), sig, rep,
        pairs,
    )  # fmt: skip


#: epochs of pseudoranges used to learn their noise, at most (evenly spread over the log)
MAX_OBS_EPOCHS = 600
#: an epoch needs this many satellites (over the 4 unknowns) to say anything of the noise
MIN_REDUNDANCY = 2


@dataclass(frozen=True)
class ObsNoise:
    """The pseudorange and rate noise a tightly coupled run used, and where it came from.

    Attributes:
        pseudorange_sigma_m, rate_sigma_mps: the 1-sigmas learned (NaN if not learned).
        source: ``reported`` (the table's per-observation sigmas), ``learned`` (single-point
            residuals of the log's own epochs) or ``default``.
        epochs: epochs the learned values come from.
    """

    pseudorange_sigma_m: float
    rate_sigma_mps: float
    source: str
    epochs: int = 0

    def as_dict(self) -> dict[str, object]:
        """JSON-ready (NaN as None)."""
        return {k: (None if isinstance(v, float) and math.isnan(v) else v)
                for k, v in asdict(self).items()}  # fmt: skip


def learn_obs(start: I64, obs: F64) -> ObsNoise:
    """Pseudorange and rate 1-sigmas from the log's own epochs: the post-fit residuals of an
    unweighted single-point solution (``ingest.gnss.spp``) over epochs with at least
    ``MIN_REDUNDANCY`` satellites beyond the four unknowns, pooled as
    ``sum(residual^2) / sum(m - 4)`` without the epochs more than 25x the median (a
    multipath burst, a bad satellite). ``start``: first row of each epoch and the end;
    ``obs``: the ``obs`` layout of ``models.measurement``."""
    n_ep = start.size - 1
    picks = np.unique(np.linspace(0, n_ep - 1, min(n_ep, MAX_OBS_EPOCHS)).astype(int))
    pr_var, pr_dof, rate_var, rate_dof = [], [], [], []
    x0 = np.zeros(spp.STATE_DIM)
    for e in picks if n_ep > 0 else ():
        rows = obs[start[e] : start[e + 1]]
        ok = rows[:, me.OB_PR_OK] > 0
        m = int(ok.sum())
        if m < spp.STATE_DIM + MIN_REDUNDANCY:
            continue
        sat = rows[ok, me.OB_SAT : me.OB_SAT + 3]
        x, _, _, conv = spp.solve_position(sat, rows[ok, me.OB_PR], np.ones(m), x0, 10, 1e-4)
        if not conv:
            continue
        res = rows[ok, me.OB_PR] - (np.linalg.norm(sat - x[:3], axis=1) + x[3])
        pr_var.append(float(res @ res))
        pr_dof.append(m - spp.STATE_DIM)
        okr = ok & (rows[:, me.OB_PRR_OK] > 0)
        mr = int(okr.sum())
        if mr < spp.STATE_DIM + MIN_REDUNDANCY:
            continue
        satr = rows[okr, me.OB_SAT : me.OB_SAT + 3]
        vel = rows[okr, me.OB_SAT + 3 : me.OB_SAT + 6]
        v, _ = spp.solve_velocity(satr, vel, rows[okr, me.OB_PRR], np.ones(mr), x[:3])
        if np.all(np.isfinite(v)):
            los = (satr - x[:3]) / np.linalg.norm(satr - x[:3], axis=1)[:, None]
            pred = np.einsum("ij,ij->i", vel - v[:3], los) + v[3]
            r = rows[okr, me.OB_PRR] - pred
            rate_var.append(float(r @ r))
            rate_dof.append(mr - spp.STATE_DIM)
    sig_pr, n_pr = _pooled(pr_var, pr_dof)
    sig_rate, _ = _pooled(rate_var, rate_dof)
    return ObsNoise(sig_pr, sig_rate, "learned" if n_pr else "default", n_pr)


def _pooled(ssr: list[float], dof: list[int]) -> tuple[float, int]:
    """sqrt(sum ssr / sum dof) over the epochs within 25x the median ssr/dof, and their
    number (NaN, 0 with fewer than 10)."""
    if len(ssr) < 10:
        return math.nan, 0
    a, d = np.asarray(ssr), np.asarray(dof, float)
    keep = a / d <= 25.0 * float(np.median(a / d))
    return math.sqrt(float(a[keep].sum() / d[keep].sum())), int(keep.sum())
