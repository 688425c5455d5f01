"""IvP objective functions as dense utility arrays over some domain variables (spec docs/spec/ivp-helm.md §4.2, §4.5)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class IvPFunction:
    """Utilities on the product grid of `vars` (array axes in that order), with priority weight `pwt`."""

    vars: tuple[str, ...]
    values: np.ndarray
    pwt: float = 100.0

    def __post_init__(self) -> None:
        if self.values.ndim != len(self.vars):
            raise ValueError(f"function over {self.vars} needs a {len(self.vars)}-d array")

    def has_nan(self) -> bool:
        return bool(np.isnan(self.values).any())


def _rescale(values: np.ndarray, top: float) -> np.ndarray:
    lo, hi = float(values.min()), float(values.max())
    if hi == lo:
        return values
    return (values - lo) * (top / (hi - lo))


def couple(f_course: IvPFunction, f_speed: IvPFunction, course_weight: float = 50.0,
           speed_weight: float = 50.0, pwt: float = 100.0) -> IvPFunction:
    """Course x speed: each rescaled to its weight, summed on the product grid, rescaled to 0..100.

    The sum is separable, so its range comes from the 1-D parts and the final rescale is folded
    into them: one outer addition is the only operation on the full grid.
    """
    c = _rescale(f_course.values, course_weight)
    s = _rescale(f_speed.values, speed_weight)
    c_lo, s_lo = float(c.min()), float(s.min())
    span = float(c.max()) - c_lo + float(s.max()) - s_lo
    if span > 0:
        k = 100.0 / span
        c, s = (c - c_lo) * k, (s - s_lo) * k
    return IvPFunction(f_course.vars + f_speed.vars, c[:, None] + s[None, :], pwt)
