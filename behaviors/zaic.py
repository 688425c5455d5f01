"""ZAIC builders: one-dimensional utility shapes over one domain variable's grid (spec docs/spec/ivp-helm.md §4.4).

Each builder returns the dense array of utilities at the variable's grid points.
"""
from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from .domain import DomainVar


class PeakComponent(NamedTuple):
    """One peak; a tuple, so that making one and hashing it (the peak cache key) cost little every helm iteration."""
    summit: float
    peakwidth: float = 0.0
    basewidth: float = 0.0
    summitdelta: float = 0.0
    minutil: float = 0.0
    maxutil: float = 100.0


def _distances(var: DomainVar, components: list[PeakComponent], value_wrap: bool) -> np.ndarray:
    """Distance of every grid point from each summit (one row per component), around the circle when
    value_wrap: computed for all components at once."""
    d = np.abs(var.values - np.array([c.summit for c in components])[:, None])
    if value_wrap:
        span = var.high - var.low + var.delta
        d = np.minimum(d, np.abs(span - d))
    return d


@functools.lru_cache(maxsize=256)
def _knot_arrays(knots: tuple) -> tuple[np.ndarray, np.ndarray]:
    """A peak's interpolation knots as arrays, made once: np.interp converts tuples on every call, at
    40 % of its cost here."""
    return np.array(knots[0]), np.array(knots[1])


def _peak(d: np.ndarray, c: PeakComponent) -> np.ndarray:
    """One component's utilities from the grid points' distances to its summit."""
    if c.minutil >= c.maxutil:
        raise ValueError(f"ZAIC_PEAK: minutil {c.minutil} must be below maxutil {c.maxutil}")
    pw, bw = max(c.peakwidth, 0.0), max(c.basewidth, 0.0)
    sd = min(c.summitdelta, c.maxutil - c.minutil) if pw > 0 else 0.0
    top = c.maxutil - sd
    if bw > 0 and sd >= 0:      # the usual shape is piecewise linear in d: one interpolation
        knots = ((0.0, pw, pw + bw), (c.maxutil, top, c.minutil)) if pw > 0 else ((0.0, bw), (c.maxutil, c.minutil))
        return np.interp(d, *_knot_arrays(knots))
    u = np.full(d.shape, c.minutil)
    if bw > 0:
        u = np.where(d <= pw + bw, top - (top - c.minutil) * (d - pw) / bw, u)
    else:
        u = np.where(d <= pw, top, u)
    if pw > 0:
        u = np.where(d <= pw, c.maxutil - sd * d / pw, u)
    else:
        u = np.where(d == 0, c.maxutil, u)
    return np.minimum(u, c.maxutil)


def zaic_peak(var: DomainVar, components: list[PeakComponent], value_wrap: bool = False,
              max_mode: bool = True, *, keep: bool = True) -> np.ndarray:
    """Peaks combined by max (default) or summed, then "summit insist" for peaks between grid points.

    Read-only: the same peaks on the same grid give the same array, kept for the next call (a
    behaviour asks for its speed peak every helm iteration, mostly with the same cruise speed).
    `keep=False` for peaks that seldom come again (a course peak on a bearing that moves every
    iteration): the same values, made afresh (writable) and not kept, so that they do not push the
    kept ones out of the cache, here and in `ivp_function.couple`'s."""
    if not keep:
        return _combined_peak(var, components, value_wrap, max_mode)
    key = (var.low, var.high, var.npts, tuple(components), value_wrap, max_mode)
    u = _PEAKS.get(key)
    if u is None:
        u = _combined_peak(var, components, value_wrap, max_mode)
        u.setflags(write=False)
        if len(_PEAKS) >= PEAK_CACHE_SIZE:
            del _PEAKS[next(iter(_PEAKS))]     # the oldest
        _PEAKS[key] = u
    return u


PEAK_CACHE_SIZE = 256
_PEAKS: dict[tuple, np.ndarray] = {}


def _combined_peak(var: DomainVar, components: list[PeakComponent], value_wrap: bool,
                   max_mode: bool) -> np.ndarray:
    d = _distances(var, components, value_wrap)
    u = _peak(d[0], components[0])
    for row, c in zip(d[1:], components[1:]):   # pairwise, as np.max / np.sum over the stacked parts, without the stack
        u = np.maximum(u, _peak(row, c)) if max_mode else u + _peak(row, c)
    # Summit insist: a flat result at a component's minutil gets that component's maxutil at its
    # summit's grid point. Flat means every point equals u[0], so no scan unless u[0] is such a minutil.
    first = next((c for c in components if c.minutil == u[0]), None)
    if first is not None and u.min() == u.max():
        u = u.copy()
        u[var.index_of(first.summit)] = first.maxutil
    return u


def zaic_hleq(var: DomainVar, summit: float, basewidth: float, summitdelta: float = 0.0,
              minutil: float = 0.0, maxutil: float = 100.0, *, leq: bool = True) -> np.ndarray:
    """ZAIC_LEQ (max at and below the summit) or ZAIC_HEQ (max at and above), linear fall over basewidth."""
    if minutil >= maxutil:
        raise ValueError(f"ZAIC_HLEQ: minutil {minutil} must be below maxutil {maxutil}")
    v = var.values
    beyond = (v - summit) if leq else (summit - v)
    bw = max(basewidth, 0.0)
    if bw > 0:
        fall = maxutil - (maxutil - minutil) * np.clip(beyond / bw, 0.0, 1.0)
    else:
        fall = np.full(v.shape, minutil)
    u = np.where(beyond <= 0, maxutil - summitdelta if summitdelta > 0 else maxutil, fall)
    if summitdelta > 0:
        u[var.index_of(summit)] = maxutil
    return np.clip(u, minutil, maxutil)


def zaic_leq(var: DomainVar, summit: float, basewidth: float, **kw) -> np.ndarray:
    return zaic_hleq(var, summit, basewidth, leq=True, **kw)


def zaic_heq(var: DomainVar, summit: float, basewidth: float, **kw) -> np.ndarray:
    return zaic_hleq(var, summit, basewidth, leq=False, **kw)
