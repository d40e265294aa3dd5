"""``experiments.vehicle_bands``: parameters of the paired speed-band Monte Carlo (paper 003).

Kept apart from ``experiments.vehicle_paired`` so that loading params.yaml imports no filter.
"""

from __future__ import annotations

from dataclasses import dataclass

from navreplay.ingest.typed import FieldError


@dataclass(frozen=True)
class VehicleBandsParams:
    """``experiments.vehicle_bands``: the paired Monte Carlo of the speed-band acceptance.

    Attributes:
        seeds: noise realizations of car_speed_ramp (seeds ``synth.seed + i``).
        confidence: of the t intervals of the paired differences.
        equivalence_rel: the equivalence margin as a fraction of the better single model's
            mean band RMS (module docstring).
        calibration_seeds: held-out realizations of the switching-speed calibration
            (``vehicle_switch_speed``), seeds ``synth.seed + calibration_seed_offset + i``.
        calibration_seed_offset: keeps those seeds disjoint from the acceptance seeds.
    """

    seeds: int = 20
    confidence: float = 0.95
    equivalence_rel: float = 0.05
    calibration_seeds: int = 20
    calibration_seed_offset: int = 1000

    def __post_init__(self) -> None:
        if self.seeds < 2:
            raise FieldError("seeds", "must be >= 2 (confidence intervals)")
        if self.calibration_seeds < 2:
            raise FieldError("calibration_seeds", "must be >= 2 (confidence intervals)")
        if self.calibration_seed_offset < self.seeds:
            raise FieldError(
                "calibration_seed_offset", "must be >= seeds (calibration seeds held out)"
            )
        if not 0.5 < self.confidence < 1.0:
            raise FieldError("confidence", "must be within (0.5, 1)")
        if not 0.0 <= self.equivalence_rel < 1.0:
            raise FieldError("equivalence_rel", "must be within [0, 1)")
