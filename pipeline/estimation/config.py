"""The ``filters`` section of params.yaml: one typed sub-section per filter of every family."""

from __future__ import annotations

from dataclasses import dataclass

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.estimation.cascaded.config import (
    CASCADED_KINDS,
    CascadedFilterParams,
    check_sections,
)
from navreplay.pipeline.estimation.ins.config import FILTER_KINDS, InsFilterParams
from navreplay.pipeline.estimation.vehicle.config import VehicleFilterParams


@dataclass(frozen=True)
class FiltersParams:
    """The ``filters`` section: one sub-section per filter of architecture section 3."""

    lc_ekf: InsFilterParams
    tc_ekf: InsFilterParams
    tc_ukf: InsFilterParams
    lc_ekf_nhc: InsFilterParams
    tc_ekf_nhc: InsFilterParams
    tc_ukf_nhc: InsFilterParams
    fwekf: InsFilterParams
    iae_ekf: InsFilterParams
    vehicle_kinematic: VehicleFilterParams
    vehicle_dynamic: VehicleFilterParams
    vehicle_switched: VehicleFilterParams
    vehicle_imm: VehicleFilterParams
    cascaded_ekf: CascadedFilterParams
    cascaded_ukf: CascadedFilterParams
    cascaded_hybrid: CascadedFilterParams

    def __post_init__(self) -> None:
        check_sections({name: getattr(self, name) for name in CASCADED_KINDS})
        for name, kind in FILTER_KINDS.items():
            section: InsFilterParams = getattr(self, name)
            if kind.nhc and section.nhc is None:
                raise FieldError(f"{name}.nhc", "missing: the _nhc filters need an nhc section")
            if not kind.nhc and section.nhc is not None:
                raise FieldError(f"{name}.nhc", "only the _nhc filters take an nhc section")
            if kind.estimator == "ukf" and section.ukf is None:
                raise FieldError(f"{name}.ukf", "missing: a UKF needs a ukf section")
            if kind.estimator != "ukf" and section.ukf is not None:
                raise FieldError(f"{name}.ukf", "only UKF filters take a ukf section")
            if kind.fading != (section.fuzzy is not None):
                raise FieldError(f"{name}.fuzzy", "fwekf needs a fuzzy section; no other filter")
            if kind.iae != (section.iae is not None):
                raise FieldError(f"{name}.iae", "iae_ekf needs an iae section; no other filter")

    def section(self, name: str) -> InsFilterParams | VehicleFilterParams | CascadedFilterParams:
        """The section of any filter ``name`` (its family's run takes it)."""
        if name not in self.__dataclass_fields__:
            known = ", ".join(self.__dataclass_fields__)
            raise KeyError(f"unknown filter {name!r} (known: {known})")
        section: InsFilterParams | VehicleFilterParams | CascadedFilterParams = getattr(self, name)
        return section

    def get(self, name: str) -> InsFilterParams:
        """The section of filter ``name`` (a key of ``FILTER_KINDS``)."""
        if name not in FILTER_KINDS:
            known = ", ".join(FILTER_KINDS)
            raise KeyError(f"unknown filter {name!r} (known: {known})")
        section: InsFilterParams = getattr(self, name)
        return section

    def cascaded(self, name: str) -> CascadedFilterParams:
        """The section of cascaded filter ``name`` (``cascaded.config.CASCADED_KINDS``)."""
        if name not in CASCADED_KINDS:
            raise KeyError(f"unknown cascaded filter {name!r} (known: {', '.join(CASCADED_KINDS)})")
        section: CascadedFilterParams = getattr(self, name)
        return section

    def vehicle(self, name: str) -> VehicleFilterParams:
        """The section of vehicle filter ``name`` (``vehicle.config.VEHICLE_FILTERS``)."""
        from navreplay.pipeline.estimation.vehicle.config import VEHICLE_FILTERS

        if name not in VEHICLE_FILTERS:
            raise KeyError(f"unknown vehicle filter {name!r} (known: {', '.join(VEHICLE_FILTERS)})")
        section: VehicleFilterParams = getattr(self, name)
        return section
