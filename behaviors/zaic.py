"""ZAIC builders: one-dimensional utility shapes over one domain variable's grid (spec docs/spec/ivp-helm.md §4.4).

Each builder returns the dense array of utilities at the variable's grid points.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .domain import DomainVar


@dataclass(frozen=True)
class PeakComponent:
    summit: float
    peakwidth: float = 0.0
    basewidth: float = 0.0
    summitdelta: float = 0.0
    minutil: float = 0.0
    maxutil: float = 100.0


def _peak(var: DomainVar, c: PeakComponent, value_wrap: bool) -> np.ndarray:
    if c.minutil >= c.maxutil:
        raise ValueError(f"ZAIC_PEAK: minutil {c.minutil} must be below maxutil {c.maxutil}")
    v = var.values
    d = np.abs(v - c.summit)
    if value_wrap:
        span = var.high - var.low + var.delta
        d = np.minimum(d, np.abs(span - d))
    pw, bw = max(c.peakwidth, 0.0), max(c.basewidth, 0.0)
    sd = min(c.summitdelta, c.maxutil - c.minutil) if pw > 0 else 0.0
    top = c.maxutil - sd
    if bw > 0 and sd >= 0:      # the usual shape is piecewise linear in d: one interpolation
        xp, fp = ((0.0, pw, pw + bw), (c.maxutil, top, c.minutil)) if pw > 0 else ((0.0, bw), (c.maxutil, c.minutil))
        return np.interp(d, xp, fp)
    u = np.full(v.shape, c.minutil)
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
              max_mode: bool = True) -> np.ndarray:
    """Peaks combined by max (default) or summed, then "summit insist" for peaks between grid points.

    Read-only: the same peaks on the same grid give the same array, kept for the next call (a
    behaviour asks for its speed peak every helm iteration, mostly with the same cruise speed)."""
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
    u = _peak(var, components[0], value_wrap)
    for c in components[1:]:      # pairwise, as np.max / np.sum over the stacked parts, without the stack
        u = np.maximum(u, _peak(var, c, value_wrap)) if max_mode else u + _peak(var, c, value_wrap)
    low, high = u.min(), u.max()
    for c in components:
        if low == high == c.minutil:
            u = u.copy()
            u[var.index_of(c.summit)] = c.maxutil
            low, high = u.min(), u.max()
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
