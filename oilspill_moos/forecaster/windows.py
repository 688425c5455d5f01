"""Forecast cases cut from simulated scenarios: what a forecaster would have been given at one
observation time (up to ``WINDOW`` noisy observations, the forcing at each, a forcing forecast over the
horizon) and the clean truth at each horizon it is scored against.

The given forcing is the scenario's erroneous ``hourly_given`` series (``exact=True``: the forcing that
moved the oil). ``held=True`` gives no forcing over the horizon, as the public API does when none is
passed: the forecaster holds the latest observation's forcing while the real forcing goes on changing. Observations carry the noise of ``Scenario.observed``. Everything is on one plane per
scenario; the forecaster only ever sees positions relative to the latest observation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import features as F
from .engine import Observations
from .physics import ForcingTrack

MAX_HORIZON_H = 15


@dataclass
class Case:
    """One forecast case: the observations up to ``end_h`` and the truth at ``end_h`` + each horizon."""

    scenario_id: str
    end_h: float
    obs: Observations
    truth: list                     # planar MultiPolygon per horizon
    truth_shapes: list[F.Shape]


def scenario_cases(scenario, horizons_h=F.HORIZONS_H, *, noise_seed: int = 0, noise: bool = True,
                   exact: bool = False, held: bool = False, stride: int = 1, min_history: int = 2, window: int = F.WINDOW) -> list[Case]:
    """Cases at every ``stride``-th observation with at least ``min_history`` observations before and
    including it and the truth known at every horizon."""
    if scenario.hourly_given is None:
        raise ValueError(f"{scenario.scenario_id}: no hourly forcing series (not a Gulf-set scenario)")
    series = scenario.hourly_true if exact else scenario.hourly_given
    index, observed = scenario.observed(noise_seed, noise)
    plane = F.SpillPlane.about(scenario.geometries[0])
    obs_planar = [plane.to_plane(F.repaired(g)) for g in observed]
    obs_shapes = [F.Shape.of(g) for g in obs_planar]
    hours = scenario.times_h
    truth_at = {float(h): i for i, h in enumerate(hours)}
    truth_cache: dict[int, tuple] = {}

    def truth(i: int):
        if i not in truth_cache:
            g = plane.to_plane(scenario.geometries[i])
            truth_cache[i] = (g, F.Shape.of(g))
        return truth_cache[i]

    cases = []
    for k in range(min_history - 1, len(index), stride):
        end = float(hours[index[k]])
        wanted = [end + h for h in horizons_h]
        if any(w not in truth_at for w in wanted) or end + MAX_HORIZON_H >= len(series):
            continue
        first = max(0, k - window + 1)
        obs_hours = hours[index[first:k + 1]]
        rows = series[obs_hours.astype(int), :4]
        ahead = np.arange(1, 0 if held else MAX_HORIZON_H + 1, dtype=float)
        track = ForcingTrack(np.concatenate([(obs_hours - end) * 3600, ahead * 3600]),
                             np.vstack([rows, series[(end + ahead).astype(int), :4]]))
        obs = Observations(plane, obs_planar[first:k + 1], obs_shapes[first:k + 1], (obs_hours - end) * 3600.0, rows, track)
        truths = [truth(truth_at[w]) for w in wanted]
        cases.append(Case(scenario.scenario_id, end, obs, [t[0] for t in truths], [t[1] for t in truths]))
    return cases
