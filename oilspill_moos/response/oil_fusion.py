"""Shoreside fusion of the fleet's oil observations: pure functions and a sans-I/O collector.

Vehicles report `OIL_OBSERVATION = "vname=abe,id=17,utc=..,x=..,y=..,oil=1,range=15[,thickness=thick]"`
(x, y in the mission's local metres, utc on the simulated world clock the sensor answered with,
range the sensor's detection radius: oil=1 means "oil within range metres"). The collector keeps
one forecast cycle's observations, throwing out (with a reason) what cannot be trusted; the
boundary estimate and the skill score compare what the vessels saw with the forecast in force.

The messages' codecs live in oilspill_moos.messages; the scenario's placement in the mission
frame in `scenario_map.ScenarioMap`.
"""
from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from moosdb_py.app import MOOSApp
from moosdb_py.config import ConfigValueError, Param, Params, read_params
from moosdb_py.formats import format_number
from moosdb_py.geodesy import mission_grid
from oilspill_moos.messages import (
    BoundaryError,
    Observation,
    ObservationRejected,
    operating_area,
    parse_observation,
    parse_polygon_string,
)
from oilspill_moos.response.scenario_map import ScenarioMap


@dataclass
class ObservationCollector:
    """One forecast cycle's observations, each vehicle's in time order, duplicates dropped.

    `fleet` empty accepts any vehicle; `area` None accepts any position. Rejections are counted
    by reason so the app's status shows what is being thrown away.
    """

    fleet: frozenset[str] = frozenset()
    area: BaseGeometry | None = None
    cycle: str = ""
    observations: list[Observation] = field(default_factory=list)
    rejected: dict[str, int] = field(default_factory=dict)
    duplicates: int = 0
    _seen: set[tuple[str, int]] = field(default_factory=set)
    _last_utc: dict[str, float] = field(default_factory=dict)

    def offer(self, obs: Observation) -> bool:
        """Keep `obs`; False for a duplicate (silently dropped); ObservationRejected for bad input."""
        if (obs.vname, obs.id) in self._seen:
            self.duplicates += 1
            return False
        if self.fleet and obs.vname not in self.fleet:
            return self._reject("unknown vehicle", f"observation from unknown vehicle {obs.vname!r}")
        if self.area is not None and not self.area.contains(shapely.Point(obs.x, obs.y)):
            return self._reject("out of area", f"{obs.vname} #{obs.id} at {obs.x:.0f},{obs.y:.0f} "
                                               f"lies outside the operating area")
        last = self._last_utc.get(obs.vname, -math.inf)
        if obs.utc < last:
            return self._reject("out of order", f"{obs.vname} #{obs.id} at utc {obs.utc:.2f} is older than "
                                                f"its previous observation ({last:.2f})")
        self._seen.add((obs.vname, obs.id))
        self._last_utc[obs.vname] = obs.utc
        self.observations.append(obs)
        return True

    def _reject(self, kind: str, reason: str) -> bool:
        self.rejected[kind] = self.rejected.get(kind, 0) + 1
        raise ObservationRejected(reason)

    def begin_cycle(self, label: str) -> list[Observation]:
        """Start a new forecast cycle; returns the observations of the one that ends. Duplicate and
        order checks carry over: a vehicle's old observation does not become new with the cycle."""
        ended, self.observations, self.cycle = self.observations, [], label
        return ended


def flip_points(observations: Iterable[Observation], max_gap_m: float = math.inf) -> list[tuple[float, float, float]]:
    """(x, y, range) half-way between consecutive samples of one vehicle whose oil flag differs.

    A flip there means the sensor's circle edge touched the spill's edge: the spill boundary lies
    about `range` metres from the point. Samples further apart than `max_gap_m` say nothing.
    """
    by_vehicle: dict[str, list[Observation]] = {}
    for obs in observations:
        by_vehicle.setdefault(obs.vname, []).append(obs)
    points = []
    for track in by_vehicle.values():
        track.sort(key=lambda o: (o.utc, o.id))
        for a, b in zip(track, track[1:]):
            if a.oil != b.oil and math.hypot(b.x - a.x, b.y - a.y) <= max_gap_m:
                points.append(((a.x + b.x) / 2, (a.y + b.y) / 2, (a.range_m + b.range_m) / 2))
    return points


def skill(forecast: BaseGeometry, observations: list[Observation], max_gap_m: float = math.inf) -> dict[str, float]:
    """How well a forecast outline explains what the vessels saw.

    agreement: share of observations the forecast predicts right (oil within range or not);
    boundary_error_m: median, over flip points, of |distance to the forecast edge - range|:
    how far the forecast edge is from where the vessels saw it; NaN without flips.
    """
    if not observations:
        return {"observations": 0, "detections": 0, "agreement": math.nan, "flips": 0, "boundary_error_m": math.nan}
    xy = np.array([(o.x, o.y) for o in observations])
    ranges = np.array([o.range_m for o in observations])
    seen = np.array([o.oil for o in observations])
    predicted = shapely.dwithin(forecast, shapely.points(xy), ranges)
    flips = flip_points(observations, max_gap_m)
    if flips:
        fx = np.array(flips)
        edge = shapely.distance(forecast.boundary, shapely.points(fx[:, :2]))
        inside = shapely.contains_xy(forecast, fx[:, 0], fx[:, 1])
        error = float(np.median(np.abs(np.where(inside, -edge, edge) - fx[:, 2])))
    else:
        error = math.nan
    return {"observations": len(observations), "detections": int(seen.sum()),
            "agreement": float(np.mean(predicted == seen)), "flips": len(flips), "boundary_error_m": error}


FUSION_PARAMS = Params(
    Param("fleet", str, "", "vehicles whose observations count, abe:ben:cal; empty: any"),
    Param("operating_area", str, "", "pts={x,y:...} observations must lie in; empty: use the radius"),
    Param("operating_radius", float, 0.0, "m about the origin observations must lie within; 0: anywhere", lo=0),
    Param("map_scale", float, 1.0, "as uFldOilSensor's: mission metres per real metre", lo=1e-6),
    Param("max_flip_gap", float, 50.0, "m: consecutive samples further apart give no edge point", lo=0),
    Param("feedback_file", str, "", "JSON-lines file for `oilspill-forecaster --feedback`; empty: none"),
    Param("report_interval", float, 5.0, "s between OIL_FUSION_SKILL / OIL_OBSERVED_EDGE posts", lo=0.1),
)


class OilFusion(MOOSApp):
    """uFldOilFusion: collects the fleet's OIL_OBSERVATION reports per forecast cycle (a new
    OILSPILL_BOUNDARY starts one), rejects unknown vehicles, positions outside the operating area
    and out-of-order reports with a reason, drops duplicates, estimates the observed spill edge
    from detection flips, scores the forecast in force against what the vessels see, and writes
    every accepted observation (in the scenario's lon/lat) to the forecaster's feedback file."""

    default_name = "uFldOilFusion"
    parameters = FUSION_PARAMS
    example_config = """\
ProcessConfig = uFldOilFusion
{
  AppTick   = 2
  CommsTick = 2

  fleet            =          // vehicles whose observations count, abe:ben:cal; empty: any
  operating_area   =          // pts={x,y:...} observations must lie in; empty: use the radius
  operating_radius = 0        // m about the origin observations must lie within; 0: anywhere
  map_scale        = 1        // as uFldOilSensor's: mission metres per real metre
  max_flip_gap     = 50       // m: consecutive samples further apart give no edge point
  feedback_file    =          // JSON-lines file for `oilspill-forecaster --feedback`; empty: none
  report_interval  = 5        // s between OIL_FUSION_SKILL / OIL_OBSERVED_EDGE posts
}
"""
    interface = """\
SUBSCRIPTIONS:
  OIL_OBSERVATION       "vname=abe,id=17,utc=..,x=..,y=..,oil=1,range=15" (bridged from pOilSampler)
  OILSPILL_BOUNDARY     the forecast boundary in force (pPathAssign); a new one starts a cycle

PUBLICATIONS:
  OIL_FUSION_SKILL      "cycle=oilspill_2,observations=..,detections=..,agreement=..,flips=..,
                        boundary_error_m=..,rejected=..,duplicates=.."
  OIL_OBSERVED_EDGE     "x,y:x,y:..." points half-way between samples whose oil flag flips
  OIL_FUSION_WARNING    a rejected observation and why
"""

    def on_startup(self) -> None:
        read_params(self.config, self._read)
        self.forecast: Polygon | None = None
        self._last_report = -math.inf

    def _read(self, cfg) -> None:
        v = FUSION_PARAMS.read(cfg)
        fleet = frozenset(n.lower() for n in re.split(r"[\s:,]+", v["fleet"]) if n)
        try:
            area = operating_area(v["operating_area"], v["operating_radius"])
        except BoundaryError as exc:
            raise ConfigValueError("operating_area", str(exc)) from None
        self.collector = ObservationCollector(fleet=fleet, area=area)
        self.max_gap, self.report_interval = v["max_flip_gap"], v["report_interval"]
        self.feedback_file = Path(v["feedback_file"]) if v["feedback_file"] else None
        grid = mission_grid(self.mission)
        self.world = ScenarioMap(grid, v["map_scale"]) if grid is not None else None
        if self.feedback_file is not None and self.world is None:
            raise ConfigValueError("feedback_file", "needs LatOrigin and LongOrigin in the mission file")

    def on_connect(self) -> None:
        self.register("OIL_OBSERVATION")
        self.register("OILSPILL_BOUNDARY")

    def on_new_mail(self, mail) -> None:
        accepted = []
        for msg in mail:
            if msg.key == "OILSPILL_BOUNDARY":
                self._new_cycle(str(msg.value))
            elif msg.key == "OIL_OBSERVATION":
                try:
                    obs = parse_observation(str(msg.value))
                    if self.collector.offer(obs):
                        accepted.append(obs)
                except ObservationRejected as exc:
                    self.notify("OIL_FUSION_WARNING", f"{msg.sender}: {exc}")
        if accepted and self.feedback_file is not None:
            self._write_feedback(accepted)

    def _new_cycle(self, spec: str) -> None:
        try:
            vertices, fields = parse_polygon_string(spec)
            polygon = shapely.make_valid(Polygon(vertices))
        except (BoundaryError, ValueError) as exc:
            self.notify("OIL_FUSION_WARNING", f"OILSPILL_BOUNDARY {spec[:60]!r}: {exc}")
            return
        self._post_report()      # the ending cycle's last word
        label = fields.get("label", "")
        self.forecast = polygon
        self.collector.begin_cycle(label)

    def _write_feedback(self, accepted: list[Observation]) -> None:
        lon, lat = self.world.to_lonlat([o.x for o in accepted], [o.y for o in accepted])
        lines = [json.dumps({"utc": o.utc, "lon": float(lo), "lat": float(la), "oil": o.oil,
                             "range_m": self.world.real_metres(o.range_m), "vname": o.vname,
                             "cycle": self.collector.cycle}) for o, lo, la in zip(accepted, lon, lat)]
        with self.feedback_file.open("a") as f:
            f.write("\n".join(lines) + "\n")

    def iterate(self) -> None:
        if self.moos_time() - self._last_report >= self.report_interval:
            self._post_report()

    def _post_report(self) -> None:
        self._last_report = self.moos_time()
        observations = self.collector.observations
        if self.forecast is None or not observations:
            return
        scores = skill(self.forecast, observations, self.max_gap)
        fields = {"cycle": self.collector.cycle, **{k: (format_number(v, 2) if isinstance(v, float) and
                                                        math.isfinite(v) else v) for k, v in scores.items()},
                  "rejected": sum(self.collector.rejected.values()), "duplicates": self.collector.duplicates}
        self.notify("OIL_FUSION_SKILL", ",".join(f"{k}={v}" for k, v in fields.items()))
        edge = flip_points(observations, self.max_gap)
        if edge:
            self.notify("OIL_OBSERVED_EDGE", ":".join(f"{x:.1f},{y:.1f}" for x, y, _ in edge))

    def status_fields(self) -> dict:
        return {"cycle": self.collector.cycle or "-", "observations": len(self.collector.observations),
                "rejected": sum(self.collector.rejected.values()), "duplicates": self.collector.duplicates}



main = OilFusion.main
