"""uFldOilSensor: the "true" spill of a simulation, and the oil sensor every vehicle carries.

In the style of MOOS-IvP's uField sensor simulators (uFldBeaconRangeSensor, uFldHazardSensor):
the shoreside holds the ground truth, a vehicle asks (`OIL_SENSOR_REQUEST`, bridged from its
community), and the answer goes back on `OIL_SENSOR_REPORT_<V>` (qbridged to the vehicle). The
truth is a scenario of the forecaster's committed OpenOil dataset: its hourly polygons replayed on
the mission's warped clock, shrunk by `map_scale` about the mission origin (see
`scenario_map.ScenarioMap`). Replies carry the simulated world's time (`utc`, the scenario clock),
so what the fleet reports can be set against the forecaster's own polygon times.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from moosdb_py.app import MOOSApp
from moosdb_py.formats import parse_pairs
from moosdb_py.config import ConfigValueError, Param, Params, read_params
from moosdb_py.geodesy import mission_grid
from oilspill_moos.messages import Observation, format_observation, parse_request, polygon_string
from oilspill_moos.response.scenario_map import ScenarioMap

THICKNESS_CLASSES = ("sheen", "thick")


@dataclass
class TruthSpill:
    """A scenario's polygons on the mission plane: hour h (since release) -> the latest hourly polygon."""

    times_h: np.ndarray
    geometries: list[BaseGeometry]      # mission metres
    release_utc: float

    @classmethod
    def from_scenario(cls, scenario, world: ScenarioMap) -> "TruthSpill":
        return cls(np.asarray(scenario.times_h, float), [world.to_local(g) for g in scenario.geometries],
                   scenario.release_time.timestamp())

    def at(self, hour: float) -> BaseGeometry:
        index = int(np.clip(np.searchsorted(self.times_h, hour, side="right") - 1, 0, len(self.times_h) - 1))
        return self.geometries[index]

    def utc(self, hour: float) -> float:
        return self.release_utc + 3600.0 * hour


@dataclass
class SensorModel:
    """Oil within `range_m` of the vehicle, flipped by false-positive / false-negative rates.

    With `thickness_depth` > 0 a detection also says how deep inside the slick the vehicle is:
    "thick" beyond that many metres from the edge, else "sheen".
    """

    range_m: float = 15.0
    false_positive: float = 0.0
    false_negative: float = 0.0
    thickness_depth: float = 0.0
    seed: int = 0

    def __post_init__(self):
        for name in ("false_positive", "false_negative"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} = {getattr(self, name)!r} must lie in [0, 1]")
        if self.range_m < 0 or self.thickness_depth < 0:
            raise ValueError("sensor_range and thickness_depth must be >= 0")
        self.rng = np.random.default_rng(self.seed)

    def sense(self, spill: BaseGeometry, x: float, y: float) -> tuple[bool, str]:
        point = shapely.Point(x, y)
        present = bool(shapely.dwithin(spill, point, self.range_m))
        flip = self.rng.random() < (self.false_negative if present else self.false_positive)
        detected = present != flip
        if not detected or self.thickness_depth <= 0:
            return detected, ""
        depth = spill.boundary.distance(point) if spill.contains(point) else 0.0
        return True, THICKNESS_CLASSES[depth >= self.thickness_depth]


SENSOR_PARAMS = Params(
    Param("scenario", str, "steady_growth-2111", "scenario_id of the committed dataset (the truth)"),
    Param("start_hour", float, 16.0, "scenario hour (since release) at the app's start", lo=0),
    Param("time_scale", float, 1.0, "scenario hours per mission hour (on top of MOOSTimeWarp)", lo=0),
    Param("map_scale", float, 1.0, "mission metres per real metre: shrinks the spill about the origin", lo=1e-6),
    Param("sensor_range", float, 15.0, "m (mission frame): \"oil\" means oil within this distance", lo=0),
    Param("false_positive", float, 0.0, "probability of reporting oil where there is none", 0, 1),
    Param("false_negative", float, 0.0, "probability of missing oil that is there", 0, 1),
    Param("thickness_depth", float, 0.0, "m inside the edge from which a detection is \"thick\"; 0: no class", lo=0),
    Param("seed", int, 0, "random seed of the sensor noise"),
    Param("truth_interval", float, 10.0, "s between VIEW_POLYGON posts of the truth (label=oil_truth)", lo=0.1),
)


class OilSensor(MOOSApp):
    """uFldOilSensor: holds a time-evolving "true" spill (a scenario of the forecaster's OpenOil
    dataset, replayed on the warped mission clock) and answers each vehicle's OIL_SENSOR_REQUEST
    with OIL_SENSOR_REPORT_<V>: oil within sensor_range or not, with false-positive and
    false-negative rates and an optional thickness class."""

    default_name = "uFldOilSensor"
    parameters = SENSOR_PARAMS
    example_config = """\
ProcessConfig = uFldOilSensor
{
  AppTick   = 4
  CommsTick = 4

  scenario        = steady_growth-2111   // scenario_id of the committed dataset (the truth)
  start_hour      = 16      // scenario hour (since release) at the app's start
  time_scale      = 1       // scenario hours per mission hour (on top of MOOSTimeWarp)
  map_scale       = 1       // mission metres per real metre: shrinks the spill about the origin
  sensor_range    = 15      // m (mission frame): "oil" means oil within this distance
  false_positive  = 0       // probability of reporting oil where there is none
  false_negative  = 0       // probability of missing oil that is there
  thickness_depth = 0       // m inside the edge from which a detection is "thick"; 0: no class
  seed            = 0       // random seed of the sensor noise
  truth_interval  = 10      // s between VIEW_POLYGON posts of the truth (label=oil_truth)
}
"""
    interface = """\
SUBSCRIPTIONS:
  OIL_SENSOR_REQUEST       "vname=abe,id=17,x=..,y=.." (pOilSampler, bridged from each vehicle)
  UFLDOILSENSOR_CMD        "hour=H": jump the truth's clock to scenario hour H

PUBLICATIONS:
  OIL_SENSOR_REPORT_<V>    "vname=abe,id=17,utc=..,x=..,y=..,oil=1,range=15[,thickness=thick]"
                           (qbridged to the vehicle as OIL_SENSOR_REPORT; utc: the scenario clock)
  VIEW_POLYGON             the true spill, label=oil_truth, for viewers and logs
  OIL_TRUTH_HOUR           the scenario hour being simulated
  OIL_SENSOR_WARNING       a request that made no sense, with the reason
"""

    def on_startup(self) -> None:
        self.grid = mission_grid(self.mission)
        if self.grid is None:
            where = self.mission.path if self.mission is not None else "no mission file"
            raise ValueError(f"{where}: needs LatOrigin and LongOrigin (the scenario is placed about them)")
        read_params(self.config, self._read)
        self.answered = self.refused = 0
        self.clock_start: float | None = None
        self._last_truth_post = -math.inf
        self._posted_index = -1

    def _read(self, cfg) -> None:
        from oilspill_moos.forecaster.dataset import load_dataset

        v = SENSOR_PARAMS.read(cfg)
        world = ScenarioMap(self.grid, v["map_scale"])
        wanted = v["scenario"]
        scenario = next((s for s in load_dataset() if s.scenario_id == wanted), None)
        if scenario is None:
            raise ConfigValueError("scenario", f"{wanted!r} is no scenario_id of the committed dataset")
        self.truth = TruthSpill.from_scenario(scenario, world)
        self.start_hour, self.time_scale, self.truth_interval = v["start_hour"], v["time_scale"], v["truth_interval"]
        self.sensor = SensorModel(range_m=v["sensor_range"], false_positive=v["false_positive"],
                                  false_negative=v["false_negative"], thickness_depth=v["thickness_depth"],
                                  seed=v["seed"])

    def on_connect(self) -> None:
        self.register("OIL_SENSOR_REQUEST")

    def hour(self) -> float:
        now = self.moos_time()
        if self.clock_start is None:
            self.clock_start = now
        return self.start_hour + (now - self.clock_start) * self.time_scale / 3600.0

    def on_new_mail(self, mail) -> None:
        for msg in mail:
            if msg.key == self.command_key:
                self._command(str(msg.value))
            if msg.key != "OIL_SENSOR_REQUEST":
                continue
            try:
                vname, ident, x, y = parse_request(str(msg.value))
            except ValueError as exc:
                self.refused += 1
                self.notify("OIL_SENSOR_WARNING", f"{msg.sender}: {exc}")
                continue
            hour = self.hour()
            oil, thickness = self.sensor.sense(self.truth.at(hour), x, y)
            report = Observation(vname, ident, self.truth.utc(hour), x, y, oil, self.sensor.range_m, thickness)
            self.notify(f"OIL_SENSOR_REPORT_{vname.upper()}", format_observation(report))
            self.answered += 1

    def _command(self, text: str) -> None:
        """`hour=H`: jump the truth's clock to scenario hour H (a demo's next forecast cycle)."""
        try:
            hour = float(parse_pairs(text)["hour"])
            if not math.isfinite(hour) or hour < 0:
                raise ValueError
        except (KeyError, ValueError):
            self.notify("OIL_SENSOR_WARNING", f"{self.command_key} {text!r}: expected hour=H (H >= 0)")
            return
        self.start_hour, self.clock_start = hour, self.moos_time()

    def iterate(self) -> None:
        hour = self.hour()
        index = int(np.searchsorted(self.truth.times_h, hour, side="right"))
        if index != self._posted_index or self.moos_time() - self._last_truth_post >= self.truth_interval:
            self._posted_index, self._last_truth_post = index, self.moos_time()
            spill = self.truth.at(hour)
            largest = max(getattr(spill, "geoms", [spill]), key=lambda p: p.area)
            self.notify("VIEW_POLYGON", polygon_string(largest, "oil_truth") + ",edge_color=brown")
            self.notify("OIL_TRUTH_HOUR", round(hour, 3))

    def status_fields(self) -> dict:
        return {"answered": self.answered, "refused": self.refused, "hour": f"{self.hour():.2f}"}



main = OilSensor.main
