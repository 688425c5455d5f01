"""Solve: the domain point maximising the priority-weighted sum of IvP functions (spec docs/spec/ivp-helm.md §4.3)."""
from __future__ import annotations

import numpy as np

from .domain import IvPDomain
from .ivp_function import IvPFunction


def _scale(f: IvPFunction) -> tuple[float, float]:
    """(lo, k): the function's utilities as the solver adds them are (u - lo) * k, its range brought to at
    most 100, then weighted by pwt. A separable function's range comes from its parts (the min of a sum
    of independent parts is the sum of their mins)."""
    if f.parts is not None:
        bounds = f.part_bounds()
        lo, hi = sum(b[0] for b in bounds), sum(b[1] for b in bounds)
    else:
        lo, hi = float(f.values.min()), float(f.values.max())
    return (lo, 100.0 / (hi - lo) * f.pwt) if hi - lo > 100.0 else (0.0, f.pwt)


def solve(domain: IvPDomain, functions: list[IvPFunction]) -> dict[str, float]:
    """One decision per variable that some function mentions; ties go to the lowest grid index.

    When every function is a sum of one-variable parts, so is their weighted total, and each variable
    is decided on its own 1-D total (the argmax of a separable sum is the argmaxes of its parts);
    otherwise the total is built on the product grid of the variables mentioned."""
    used = [f for f in functions if f.pwt > 0]
    separable = True
    for f in used:
        if f.parts is None:
            separable = False
            break
    if separable:     # each variable's 1-D total, summed in the functions' order; decided in the domain's
        totals: dict[str, np.ndarray] = {}
        for f in used:
            k = _scale(f)[1]
            for name, part in zip(f.vars, f.parts):
                total = totals.get(name)
                totals[name] = part * k if total is None else total + part * k
        decision = {}
        for var in domain.vars:
            total = totals.get(var.name)
            if total is not None:
                decision[var.name] = var.decision(int(total.argmax()))
        return decision
    names = [n for n in domain.names if any(n in f.vars for f in used)]
    if not names:
        return {}
    shape = tuple(domain.var(n).npts for n in names)
    total = np.zeros(shape)
    for f in used:
        lo, k = _scale(f)
        axes = [names.index(v) for v in f.vars]
        arr = np.transpose((f.values - lo) * k, np.argsort(axes))
        full_shape = [1] * len(names)
        for ax in sorted(axes):
            full_shape[ax] = shape[ax]
        total += arr.reshape(full_shape)
    index = np.unravel_index(int(total.argmax()), shape)
    return {n: domain.var(n).decision(i) for n, i in zip(names, index)}


def missing_decisions(domain: IvPDomain, decision: dict[str, float]) -> list[str]:
    return [v.name for v in domain.vars if not v.optional and v.name not in decision]
