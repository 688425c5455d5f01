"""Solve: the domain point maximising the priority-weighted sum of IvP functions (spec docs/spec/ivp-helm.md §4.3)."""
from __future__ import annotations

import numpy as np

from .domain import IvPDomain
from .ivp_function import IvPFunction


def _normalised(f: IvPFunction) -> np.ndarray:
    lo, hi = float(f.values.min()), float(f.values.max())
    v = f.values
    if hi - lo > 100.0:
        v = (v - lo) * (100.0 / (hi - lo))
    return v * f.pwt


def solve(domain: IvPDomain, functions: list[IvPFunction]) -> dict[str, float]:
    """One decision per variable that some function mentions; ties go to the lowest grid index."""
    used = [f for f in functions if f.pwt > 0]
    names = [n for n in domain.names if any(n in f.vars for f in used)]
    if not names:
        return {}
    shape = tuple(domain.var(n).npts for n in names)
    total = np.zeros(shape)
    for f in used:
        axes = [names.index(v) for v in f.vars]
        order = np.argsort(axes)
        arr = np.transpose(_normalised(f), order)
        full_shape = [1] * len(names)
        for ax in sorted(axes):
            full_shape[ax] = shape[ax]
        total += arr.reshape(full_shape)
    index = np.unravel_index(int(np.argmax(total)), shape)
    return {n: round(float(domain.var(n).values[i]), 9) for n, i in zip(names, index)}


def missing_decisions(domain: IvPDomain, decision: dict[str, float]) -> list[str]:
    return [v.name for v in domain.vars if not v.optional and v.name not in decision]
