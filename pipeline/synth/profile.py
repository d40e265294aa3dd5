"""Smooth scalar profiles of time: holds joined by quintic "smootherstep" transitions.

A transition from ``a`` to ``b`` over ``[t0, t0 + T]`` follows
``a + (b - a) (10 x^3 - 15 x^4 + 6 x^5)``, ``x = (t - t0) / T``, whose first and second
derivatives vanish at both ends, so a profile is C2 and its derivative is C1. Profiles are
``scipy.interpolate.PPoly`` objects: derivatives and antiderivatives are exact polynomials.
The peak slope of a transition is ``15/8 (b - a) / T``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from scipy.interpolate import PPoly

PEAK_SLOPE_FACTOR = 15.0 / 8.0


@dataclass
class ProfileBuilder:
    """Builds a profile by appending holds and transitions in time order, from ``t = 0``.

    Attributes:
        value: the current value (where the next segment starts).
        t: the current time, s.
    """

    value: float = 0.0
    t: float = 0.0
    _breaks: list[float] = field(default_factory=lambda: [0.0])
    _coefs: list[list[float]] = field(default_factory=list)

    def hold(self, duration_s: float) -> None:
        """Keep the current value for ``duration_s`` (no-op for zero)."""
        if duration_s <= 0.0:
            return
        self._coefs.append([0.0, 0.0, 0.0, 0.0, 0.0, self.value])
        self._advance(duration_s)

    def ramp(self, target: float, duration_s: float) -> None:
        """Move smoothly to ``target`` over ``duration_s`` (C2 at both ends)."""
        if duration_s <= 0.0:
            raise ValueError("a transition needs a positive duration")
        d, T = target - self.value, duration_s
        self._coefs.append(
            [6.0 * d / T**5, -15.0 * d / T**4, 10.0 * d / T**3, 0.0, 0.0, self.value]
        )
        self.value = target
        self._advance(duration_s)

    def _advance(self, duration_s: float) -> None:
        self.t += duration_s
        self._breaks.append(self.t)

    def build(self, t_end: float) -> PPoly:
        """The profile on ``[0, max(t, t_end)]``, holding the last value up to ``t_end``."""
        from scipy.interpolate import PPoly  # slow to import: only when building

        if self.t < t_end:
            self.hold(t_end - self.t)
        if not self._coefs:
            self.hold(1.0)
        coefs = np.array(self._coefs, dtype=np.float64).T
        return PPoly(coefs, np.array(self._breaks, dtype=np.float64), extrapolate=True)
