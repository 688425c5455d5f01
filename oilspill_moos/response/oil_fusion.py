"""Shoreside fusion of the fleet's oil observations: pure functions and a sans-I/O collector.

Vehicles report `OIL_OBSERVATION = "vname=abe,id=17,utc=..,x=..,y=..,oil=1,range=15[,thickness=thick]"`
(x, y in the mission's local metres, utc on the simulated world clock the sensor answered with,
range the sensor's detection radius: oil=1 means "oil within range metres"). The collector keeps
one forecast cycle's observations, throwing out (with a reason) what cannot be trusted; the
boundary estimate and the skill score compare what the vessels saw with the forecast in force.

`ScenarioMap` ties the mission's local frame to the world of a spill scenario: a simulated
fleet cannot circle a 10 km slick at 2 m/s in a test, so the scenario is shrunk about the
mission origin by `map_scale` (1 = true size); everything that crosses between the MOOS side and
the forecaster goes through it.
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
from oilspill_moos.app_config import (ConfigValueError, config_float, config_str, format_number, parse_pairs, read_params,
                                      warn_unhandled)
from oilspill_moos.geodesy import LocalGrid, mission_grid


class ObservationRejected(ValueError):
    """An observation the fusion will not use; str() is the reason posted in OIL_FUSION_WARNING."""


@dataclass(frozen=True)
class Observation:
    vname: str
    id: int
    utc: float
    x: float
    y: float
    oil: bool
    range_m: float = 0.0
    thickness: str = ""


def parse_observation(text: str) -> Observation:
    """`vname=abe,id=3,utc=..,x=..,y=..,oil=1,range=..` -> Observation, or ObservationRejected saying why."""
    try:
        fields = parse_pairs(text)
    except ValueError as exc:
        raise ObservationRejected(f"malformed observation {text!r}: {exc}") from None
    missing = [k for k in ("vname", "id", "utc", "x", "y", "oil") if k not in fields]
    if missing:
        raise ObservationRejected(f"observation {text!r} lacks {', '.join(missing)}")
    try:
        obs = Observation(vname=fields["vname"].lower(), id=int(fields["id"]), utc=float(fields["utc"]),
                          x=float(fields["x"]), y=float(fields["y"]), oil=_flag(fields["oil"]),
                          range_m=float(fields.get("range", 0.0)), thickness=fields.get("thickness", ""))
    except ValueError:
        raise ObservationRejected(f"observation {text!r}: id, utc, x, y, range must be numbers, oil 0 or 1") from None
    if not all(map(math.isfinite, (obs.utc, obs.x, obs.y, obs.range_m))) or obs.range_m < 0:
        raise ObservationRejected(f"observation {text!r}: non-finite number or negative range")
    return obs


def _flag(text: str) -> bool:
    if text.lower() in ("1", "true"):
        return True
    if text.lower() in ("0", "false"):
        return False
    raise ValueError(text)


def format_observation(obs: Observation) -> str:
    text = (f"vname={obs.vname},id={obs.id},utc={obs.utc:.2f},x={format_number(obs.x)},y={format_number(obs.y)},"
            f"oil={int(obs.oil)},range={format_number(obs.range_m)}")
    return text + (f",thickness={obs.thickness}" if obs.thickness else "")


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


@dataclass(frozen=True)
class ScenarioMap:
    """Mission local metres <-> a scenario's lon/lat, the scenario shrunk by `map_scale` about the origin."""

    grid: LocalGrid
    map_scale: float = 1.0

    def __post_init__(self):
        if not (math.isfinite(self.map_scale) and self.map_scale > 0):
            raise ValueError(f"map_scale {self.map_scale!r} must be a positive number")

    def to_lonlat(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        lat, lon = self.grid.to_latlon(np.asarray(x, float) / self.map_scale, np.asarray(y, float) / self.map_scale)
        return np.asarray(lon), np.asarray(lat)

    def to_local(self, geometry: BaseGeometry) -> BaseGeometry:
        """An EPSG:4326 geometry ([lon, lat] coordinates) in mission metres."""
        def forward(coords):
            x, y = self.grid.to_local(coords[:, 1], coords[:, 0])
            return np.column_stack([x, y]) * self.map_scale
        return shapely.transform(geometry, forward)

    def real_metres(self, metres: float) -> float:
        return metres / self.map_scale


def polygon_string(polygon: Polygon, label: str) -> str:
    """A MOOS `pts={x,y:...},label=..` spec of a polygon's exterior, for viewers."""
    coords = np.asarray(polygon.exterior.coords)[:-1]
    return "pts={" + ":".join(f"{x:.1f},{y:.1f}" for x, y in coords) + "}," + f"label={label}"


class OilFusion(MOOSApp):
    """uFldOilFusion: collects the fleet's OIL_OBSERVATION reports per forecast cycle (a new
    OILSPILL_BOUNDARY starts one), rejects unknown vehicles, positions outside the operating area
    and out-of-order reports with a reason, drops duplicates, estimates the observed spill edge
    from detection flips, scores the forecast in force against what the vessels see, and writes
    every accepted observation (in the scenario's lon/lat) to the forecaster's feedback file."""

    default_name = "uFldOilFusion"
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
        warn_unhandled(self.config, FUSION_CONFIG_KEYS)
        self.forecast: Polygon | None = None
        self._last_report = -math.inf

    def _read(self, cfg) -> None:
        from oilspill_moos.response.path_assign import BoundaryError, operating_area

        fleet = frozenset(n.lower() for n in re.split(r"[\s:,]+", config_str(cfg, "fleet", "")) if n)
        try:
            area = operating_area(config_str(cfg, "operating_area", ""),
                                  config_float(cfg, "operating_radius", 0.0, lo=0))
        except BoundaryError as exc:
            raise ConfigValueError("operating_area", str(exc)) from None
        self.collector = ObservationCollector(fleet=fleet, area=area)
        self.max_gap = config_float(cfg, "max_flip_gap", 50.0, lo=0)
        self.report_interval = config_float(cfg, "report_interval", 5.0, lo=0.1)
        feedback = config_str(cfg, "feedback_file", "")
        self.feedback_file = Path(feedback) if feedback else None
        grid = mission_grid(self.mission)
        self.world = ScenarioMap(grid, config_float(cfg, "map_scale", 1.0, lo=1e-6)) if grid is not None else None
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
        from oilspill_moos.response.path_assign import BoundaryError, parse_polygon_spec

        try:
            polygon = shapely.make_valid(Polygon(parse_polygon_spec(spec)))
        except (BoundaryError, ValueError) as exc:
            self.notify("OIL_FUSION_WARNING", f"OILSPILL_BOUNDARY {spec[:60]!r}: {exc}")
            return
        self._post_report()      # the ending cycle's last word
        label = parse_pairs(spec.partition("}")[2].lstrip(",")).get("label", "")
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
        fields = {"cycle": self.collector.cycle, **{k: (format_number(v) if isinstance(v, float) and
                                                        math.isfinite(v) else v) for k, v in scores.items()},
                  "rejected": sum(self.collector.rejected.values()), "duplicates": self.collector.duplicates}
        self.notify("OIL_FUSION_SKILL", ",".join(f"{k}={v}" for k, v in fields.items()))
        edge = flip_points(observations, self.max_gap)
        if edge:
            self.notify("OIL_OBSERVED_EDGE", ":".join(f"{x:.1f},{y:.1f}" for x, y, _ in edge))

    def status_fields(self) -> dict:
        return {"cycle": self.collector.cycle or "-", "observations": len(self.collector.observations),
                "rejected": sum(self.collector.rejected.values()), "duplicates": self.collector.duplicates}


FUSION_CONFIG_KEYS = frozenset({
    "fleet", "operating_area", "operating_radius", "max_flip_gap", "report_interval", "feedback_file", "map_scale"})

main = OilFusion.main
