"""IvP objective functions as dense utility arrays over some domain variables (spec docs/spec/ivp-helm.md §4.2, §4.5)."""
from __future__ import annotations

import functools

import numpy as np


class IvPFunction:
    """Utilities on the product grid of `vars` (array axes in that order), with priority weight `pwt`.

    A function made as a sum of one-dimensional parts, one per variable (what `couple` makes), keeps
    its `parts`: the solver then works on them alone, and the dense grid is built only if asked for.
    """

    __slots__ = ("vars", "pwt", "parts", "_values")

    def __init__(self, vars: tuple[str, ...], values: np.ndarray | None = None, pwt: float = 100.0, *,
                 parts: tuple[np.ndarray, ...] | None = None):
        self.vars, self.pwt, self.parts, self._values = vars, pwt, parts, values
        if values is None and (parts is None or len(parts) != len(vars)):
            raise ValueError(f"function over {vars} needs values or one part per variable")
        if values is not None and values.ndim != len(vars):
            raise ValueError(f"function over {vars} needs a {len(vars)}-d array")
        if values is not None and len(vars) == 1:
            self.parts = (values,)

    @property
    def values(self) -> np.ndarray:
        if self._values is None:
            grids = np.ix_(*self.parts)
            self._values = functools.reduce(np.add, grids)
        return self._values

    def has_nan(self) -> bool:
        if self.parts is not None:
            return any(bool(np.isnan(p).any()) for p in self.parts)
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
    into them: the result keeps the parts, and the full grid is built only if someone reads it.
    """
    c = _rescale(f_course.values, course_weight)
    s = _rescale(f_speed.values, speed_weight)
    c_lo, s_lo = float(c.min()), float(s.min())
    span = float(c.max()) - c_lo + float(s.max()) - s_lo
    if span > 0:
        k = 100.0 / span
        c, s = (c - c_lo) * k, (s - s_lo) * k
    return IvPFunction(f_course.vars + f_speed.vars, pwt=pwt, parts=(c, s))
