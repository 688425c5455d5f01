"""IvP objective functions as dense utility arrays over some domain variables (spec docs/spec/ivp-helm.md §4.2, §4.5)."""
from __future__ import annotations

import functools
import math

import numpy as np


class IvPFunction:
    """Utilities on the product grid of `vars` (array axes in that order), with priority weight `pwt`.

    A function made as a sum of one-dimensional parts, one per variable (what `couple` makes), keeps
    its `parts`: the solver then works on them alone, and the dense grid is built only if asked for.
    `bounds`, when its maker knows them, are each part's exact (min, max): the solver and the NaN
    check read them instead of scanning the parts again every helm iteration.
    """

    __slots__ = ("vars", "pwt", "parts", "bounds", "_values")

    def __init__(self, vars: tuple[str, ...], values: np.ndarray | None = None, pwt: float = 100.0, *,
                 parts: tuple[np.ndarray, ...] | None = None,
                 bounds: tuple[tuple[float, float], ...] | None = None):
        self.vars, self.pwt, self.parts, self.bounds, self._values = vars, pwt, parts, bounds, values
        if values is None and (parts is None or len(parts) != len(vars)):
            raise ValueError(f"function over {vars} needs values or one part per variable")
        if values is not None and values.ndim != len(vars):
            raise ValueError(f"function over {vars} needs a {len(vars)}-d array")
        if values is not None and len(vars) == 1:
            self.parts = (values,)
        if bounds is not None and (self.parts is None or len(bounds) != len(self.parts)):
            raise ValueError(f"function over {vars}: bounds need one (min, max) per part")

    @property
    def values(self) -> np.ndarray:
        if self._values is None:
            grids = np.ix_(*self.parts)
            self._values = functools.reduce(np.add, grids)
        return self._values

    def part_bounds(self) -> tuple[tuple[float, float], ...]:
        """(min, max) of each part (np.min/np.max: NaN when the part holds a NaN)."""
        if self.bounds is None:
            self.bounds = tuple(_range(p) for p in self.parts)
        return self.bounds

    def has_nan(self) -> bool:
        if self.parts is not None:
            return any(math.isnan(lo) for lo, _ in self.part_bounds())
        return bool(np.isnan(self.values).any())


def _range(values: np.ndarray) -> tuple[float, float]:
    """(min, max), NaN when values hold one: ndarray.min/max without their Python-level wrappers."""
    return float(np.minimum.reduce(values, axis=None)), float(np.maximum.reduce(values, axis=None))


def _shift_scale(values: np.ndarray, lo: float, hi: float, k: float) -> tuple[np.ndarray, float, float]:
    """(values - lo) * k with its (min, max), where lo and hi are the min and max of values.

    IEEE rounding is monotone, so for finite hi - lo and a finite k >= 0 the min and max map to
    (lo - lo) * k and (hi - lo) * k exactly: no scan needed. Otherwise (NaN, infinities) they are measured.
    Shifting by 0 and scaling by 1 (`couple`'s second step, mostly) leaves the values as they are: no copy."""
    if lo == 0.0 and k == 1.0:
        return values, lo, hi
    out = (values - lo) * k
    if k >= 0 and math.isfinite(k) and math.isfinite(hi - lo):
        return out, (lo - lo) * k, (hi - lo) * k
    return (out, *_range(out))


def _rescale(values: np.ndarray, top: float) -> tuple[np.ndarray, float, float]:
    """values brought to 0..top, with the result's (min, max); a flat array is left as it is."""
    lo, hi = _range(values)
    if hi == lo:
        return values, lo, hi
    return _shift_scale(values, lo, hi, top / (hi - lo))


def _rescale_kept(values: np.ndarray, top: float) -> tuple[np.ndarray, float, float]:
    """`_rescale`, kept for a read-only array (a ZAIC kept by `zaic_peak`: a behaviour's speed peak, the same
    array every helm iteration while its cruise speed holds) and handed out read-only; a writable array is
    rescaled every time (its values may change)."""
    if values.flags.writeable:
        return _rescale(values, top)
    key = (id(values), top)
    kept = _RESCALED.get(key)
    if kept is not None and kept[0] is values:   # the entry holds the array: its id is not reused meanwhile
        return kept[1]
    out, lo, hi = _rescale(values, top)
    if out is not values:
        out.setflags(write=False)
    if len(_RESCALED) >= RESCALED_KEPT:
        del _RESCALED[next(iter(_RESCALED))]     # the oldest
    _RESCALED[key] = (values, (out, lo, hi))
    return out, lo, hi


RESCALED_KEPT = 256
_RESCALED: dict[tuple[int, float], tuple[np.ndarray, tuple[np.ndarray, float, float]]] = {}


def couple(f_course: IvPFunction, f_speed: IvPFunction, course_weight: float = 50.0,
           speed_weight: float = 50.0, pwt: float = 100.0) -> IvPFunction:
    """Course x speed: each rescaled to its weight, summed on the product grid, rescaled to 0..100.

    The sum is separable, so its range comes from the 1-D parts and the final rescale is folded
    into them: the result keeps the parts (and their exact bounds), and the full grid is built
    only if someone reads it.
    """
    c, c_lo, c_hi = _rescale_kept(f_course.values, course_weight)
    s, s_lo, s_hi = _rescale_kept(f_speed.values, speed_weight)
    span = c_hi - c_lo + s_hi - s_lo
    if span > 0:
        k = 100.0 / span
        c, c_lo, c_hi = _shift_scale(c, c_lo, c_hi, k)
        s, s_lo, s_hi = _shift_scale(s, s_lo, s_hi, k)
    return IvPFunction(f_course.vars + f_speed.vars, pwt=pwt, parts=(c, s), bounds=((c_lo, c_hi), (s_lo, s_hi)))
