"""``experiments.tractor_cascaded`` of params.yaml: the paper 000 experiment's settings.

Kept apart from ``runs`` so that loading params.yaml does not import (and, on a cold numba
cache, compile) the cascaded filters.
"""

from __future__ import annotations

from dataclasses import dataclass

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.estimation.cascaded.config import CASCADED_KINDS

#: the EKF linearized about psi_d (paper 000 eq. 17 as printed); nominal runs only
PSI_D_LABEL = "cascaded_ekf_psi_d"
BASELINE = "cascaded_ekf"
NOMINAL = "nominal"


@dataclass(frozen=True)
class TractorExperimentParams:
    """``experiments.tractor_cascaded``.

    Attributes:
        filters: cascaded filters to run (names of ``filters.*`` sections).
        paper_linearization: also run ``cascaded_ekf_psi_d`` (nominal scenario).
        sensitivity_noise_interval_s: also run every filter (every scenario) with Table 1's
            variances accumulating over these intervals instead of the section's
            ``process_noise.interval_s`` (label ``<filter>@q<interval>s``), e.g. 0.02: Table 1
            read literally as the variance of one 0.02 s step (``estimation.cascaded.config``
            discusses the two readings).
        seeds: Monte Carlo runs per filter and scenario.
        outage_start_s: start of the GPS outage (after the biases have converged), s.
        outage_lengths_s: one outage scenario per length, s (paper's question: drift).
        settle_s: tracking and position errors are also reported after this time, s.
        step_tolerance_m: the 3 m step counts as recovered once the true lateral error
            stays below this until the outage (or the end), m.
        confidence: level of the confidence intervals (e.g. 0.95).
        equivalence_s: differences of convergence times whose whole confidence interval
            lies within +-this count as "no practical difference", s.
        equivalence_m: the same for position errors and drifts, m.
        workers: processes for the Monte Carlo runs.
        example_seed: the Monte Carlo run shown in the time-series figures.
        timeseries_rate_hz: rate of the time-series CSV files (decimated from 50 Hz).
    """

    filters: tuple[str, ...] = ("cascaded_ekf", "cascaded_ukf", "cascaded_hybrid")
    paper_linearization: bool = True
    sensitivity_noise_interval_s: tuple[float, ...] = (0.02,)
    seeds: int = 40
    outage_start_s: float = 40.0
    outage_lengths_s: tuple[float, ...] = (10.0, 20.0)
    settle_s: float = 10.0
    step_tolerance_m: float = 0.1
    confidence: float = 0.95
    equivalence_s: float = 0.5
    equivalence_m: float = 0.005
    workers: int = 2
    example_seed: int = 0
    timeseries_rate_hz: float = 10.0

    def __post_init__(self) -> None:
        for f in self.filters:
            if f not in CASCADED_KINDS:
                raise FieldError("filters", f"{f!r} is not a cascaded filter")
        if BASELINE not in self.filters:
            raise FieldError("filters", f"must include {BASELINE} (the paired baseline)")
        if any(not v > 0 for v in self.sensitivity_noise_interval_s):
            raise FieldError("sensitivity_noise_interval_s", "intervals must be > 0")
        if self.seeds < 2:
            raise FieldError("seeds", "must be >= 2 (confidence intervals)")
        if not 0.5 < self.confidence < 1.0:
            raise FieldError("confidence", "must be within (0.5, 1)")
        if self.workers < 1:
            raise FieldError("workers", "must be >= 1")
        if not 0 <= self.example_seed < self.seeds:
            raise FieldError("example_seed", "must be a Monte Carlo run index")
        if not self.timeseries_rate_hz > 0:
            raise FieldError("timeseries_rate_hz", "must be > 0")

    def scenarios(self) -> dict[str, tuple[tuple[float, float], ...]]:
        """Scenario name -> GPS outage windows."""
        out: dict[str, tuple[tuple[float, float], ...]] = {NOMINAL: ()}
        for length in self.outage_lengths_s:
            out[f"outage_{length:g}s"] = ((self.outage_start_s, self.outage_start_s + length),)
        return out
