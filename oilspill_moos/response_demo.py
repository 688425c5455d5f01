"""`make demo`: a spill response at real scale, judged against a truth spill.

A held-out scenario of the forecaster's dataset is the truth: uFldOilSensor replays it on the
mission clock (map_scale 1, real metres about the Deepwater Horizon wellhead) and the demo keeps the
same truth for its measures. Every `cycle_h` mission hours a forecast cycle starts: the forecaster
(`Forecaster(...).forecast`) forecasts 3/7/11/15 h ahead from the truth's hourly outlines up to that
hour, as a satellite pass would give them, and the four lines go to pPathAssign, which halts the
fleet, re-plans from where the vessels are and gives each vessel its own arc of the stand-off loop.
While it runs the demo prints the measures (oil/measures.py) and at the end a summary; the run's
record (report.json) becomes report.html with its PNGs (oilspill_moos/response_report.py).
"""
from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from shapely.geometry import Polygon

from moosdb_py.geodesy import LocalGrid
from oilspill_moos.demo import status_horizon
from oilspill_moos.forecaster.kinds import DEFAULT_MODEL
from oilspill_moos.forecaster.push import BoundaryPusher
from oilspill_moos.messages import parse_boundary_line
from oilspill_moos.oilspill_mission import ORIGIN, Observer, OilspillMission, TickWatch, wait_for
from oilspill_moos.response.measures import (
    largest_revisit_gap,
    manned_at,
    oil_containment,
    patrol_offsets,
    perimeter_coverage,
    positions_at,
)
from oilspill_moos.response.scenario_map import ScenarioMap
from oilspill_moos.response.oil_sensor import TruthSpill
from oilspill_moos.response.path_assign import OIL_PATH, STARTING_POSITION, STATION_KEEPING
from oilspill_moos.response.planner import containment_region

SCENARIO = "strong_forcing-2214"   # in the shipped weights' test split: the forecaster never saw it
START_HOUR = 17.0                  # scenario hour (since release) when the mission starts
STANDOFF = 500.0                   # m the loop keeps outside the forecast outline
TOP_SPEED = 4.0                    # m/s: the helm's domain (speed:0:4) and the transit speed
LOOP_SPEED = 3.0                   # m/s on the arcs
REACH = 1000.0                     # m: a vessel "covers" the perimeter within this distance
CAPTURE = 50.0                     # m from its arc that counts as on it (the manning measure)
BOUND_FACTOR = 1.3


@dataclass
class Truth:
    """The scenario on the mission plane (uFldOilSensor's TruthSpill), on the mission clock: hour
    `start_hour` at mission second 0."""

    scenario: object
    spill: TruthSpill
    start_hour: float = START_HOUR

    def observed(self, hour: float) -> int:
        """How many hourly outlines exist by scenario hour `hour` (what a satellite has seen)."""
        return max(int(np.searchsorted(self.spill.times_h, hour, side="right")), 1)

    def hour(self, mission_s: float) -> float:
        return self.start_hour + mission_s / 3600.0

    def at_hour(self, hour: float):
        return self.spill.at(hour)

    def at(self, mission_s: float):
        return self.spill.at(self.hour(mission_s))


def load_truth(scenario_id: str = SCENARIO, start_hour: float = START_HOUR) -> Truth:
    from oilspill_moos.forecaster.dataset import load_dataset

    scenario = next((s for s in load_dataset() if s.scenario_id == scenario_id), None)
    if scenario is None:
        raise RuntimeError(f"scenario {scenario_id!r} is not in the forecaster's dataset")
    return Truth(scenario, TruthSpill.from_scenario(scenario, ScenarioMap(LocalGrid(*ORIGIN), 1.0)), start_hour)


@dataclass
class CycleForecast:
    """One forecast cycle: the lines to push and, per horizon, the outline in mission metres."""

    number: int
    push_s: float                   # mission second of the push
    issued_hour: float              # scenario hour of the last observation used
    lines: list[bytes]
    horizons: dict[float, dict]     # horizon_h -> {"polygon", "uncertainty_m", "valid_hour"}


def forecast_cycles(truth: Truth, cycles: int, cycle_h: float, weights: Path | None, kind: str) -> list[CycleForecast]:
    """The forecaster's cycles: at mission hour k·cycle_h it sees the truth's hourly outlines up to
    that hour (a satellite pass each hour) and forecasts every horizon it has."""
    from oilspill_moos.forecaster.operational import Forecaster

    forecaster = Forecaster(weights, kind) if weights is not None else Forecaster(kind=kind)
    grid = LocalGrid(*ORIGIN)
    scenario = truth.scenario
    found = []
    for k in range(cycles):
        last = truth.observed(truth.start_hour + k * cycle_h)
        history = scenario.geometries[:last], scenario.times()[:last], scenario.environments()[:last]
        forecasts = forecaster.forecast(*history, scenario.release_time)
        lines = [f.line() for f in forecasts]
        horizons = {}
        for line, f in zip(lines, forecasts):
            boundary = parse_boundary_line(line.decode(), grid)
            horizons[f.horizon_h] = {"polygon": [list(p) for p in boundary.polygon],
                                     "uncertainty_m": f.uncertainty_m,
                                     "valid_hour": float(scenario.times_h[last - 1]) + f.horizon_h}
        found.append(CycleForecast(k + 1, k * cycle_h * 3600.0, float(scenario.times_h[last - 1]), lines, horizons))
    return found


def stations(outline: list, vehicles: int, distance: float) -> list[tuple[float, float]]:
    """Where the fleet waits at the start: evenly round the first forecast, `distance` m beyond the loop."""
    ring = containment_region(outline, STANDOFF + distance).exterior
    return [tuple(ring.interpolate(ring.length * (i + 0.5) / vehicles).coords[0]) for i in range(vehicles)]


def forecast_skill(truth: Truth, horizons: dict[float, dict]) -> dict[str, dict]:
    """Per horizon: IoU with the truth at the valid hour and the centroid error (km)."""
    skill = {}
    for horizon, h in sorted(horizons.items()):
        forecast, real = Polygon(h["polygon"]).buffer(0), truth.at_hour(h["valid_hour"])
        union = forecast.union(real).area
        skill[f"{horizon:g}"] = {"iou": round(forecast.intersection(real).area / union, 3) if union else 0.0,
                                 "centroid_error_km": round(forecast.centroid.distance(real.centroid) / 1000, 2),
                                 "valid_hour": h["valid_hour"]}
    return skill


def patrolling(observer: Observer) -> set[str]:
    return {name for name, mode in observer.modes.items() if mode.endswith(OIL_PATH)}


def geometry_rings(geometry) -> list[list[list[float]]]:
    """The exterior rings of every part, rounded to the metre (the report's JSON)."""
    return [np.round(np.asarray(p.exterior.coords), 0).tolist() for p in getattr(geometry, "geoms", [geometry])]


@dataclass
class ResponseRun:
    """What the demo keeps while it runs: measure samples and, per cycle, phases, plan and measures."""

    truth: Truth
    observer: Observer
    reach: float = REACH
    samples: list[dict] = field(default_factory=list)
    cycles: list[dict] = field(default_factory=list)
    last_print: float = -math.inf

    def mission_s(self) -> float:
        return self.observer.client.moos_time() - self.observer.t0

    def measure_sample(self, t: float, recent: dict, moos_now: float, region) -> dict:
        """Coverage and oil inside the loop at mission second `t`, from the recent tracks of the patrolling
        vessels and the loop in force (pure: runs off the event loop)."""
        spill = self.truth.at(t)
        now = positions_at(recent, moos_now, stale=60.0)
        entry = {"mission_s": round(t, 1), "hour": round(self.truth.hour(t), 3), "patrolling": len(now),
                 "coverage": round(perimeter_coverage(spill, list(now.values()), self.reach), 4)}
        if region is not None:
            entry["oil_inside"] = round(oil_containment(spill, region).share_inside, 4)
        return entry

    def _sampled(self, entry: dict) -> dict:
        """Keep a sample; print it every 15 mission minutes."""
        self.samples.append(entry)
        t = entry["mission_s"]
        if t - self.last_print >= 900:
            self.last_print = t
            inside = f", true oil inside the loop {100 * entry['oil_inside']:.0f} %" if "oil_inside" in entry else ""
            self.observer.say("measure", f"{100 * entry['coverage']:.0f} % of the true perimeter within "
                                         f"{self.reach / 1000:g} km of a patrolling vessel "
                                         f"({entry['patrolling']} patrolling){inside}")
        return entry

    async def sampler(self, every_s: float) -> None:
        """A sample every `every_s` mission seconds, for as long as the run lasts. The measures are
        computed in a worker thread from a snapshot, so the observer's client keeps its DB
        connection alive meanwhile (a blocked event loop sends no timing message: the DB's client
        time-out drops it)."""
        next_at = 0.0
        while True:
            if self.mission_s() >= next_at:
                t, observer = self.mission_s(), self.observer
                recent = {n: observer.tracks[n][-20:] for n in patrolling(observer) if n in observer.tracks}
                region = observer.regions[-1] if observer.regions else None
                self._sampled(await asyncio.to_thread(self.measure_sample, t, recent, observer.client.moos_time(),
                                                      region))
                next_at = self.mission_s() + every_s
            await asyncio.sleep(0.2)

    async def close_cycle(self, cycle: dict, end_s: float) -> None:
        """The cycle's measures once its patrol time is over (every value JSON-ready), computed in a
        worker thread from a snapshot of what the observer holds (see `sampler`)."""
        observer = self.observer
        tracks = {n: list(track) for n, track in observer.tracks.items()}
        patrols = {n: [list(p) for p in points] for n, points in observer.loops.items()}
        region = observer.regions[-1] if observer.regions else None
        samples = list(self.samples)
        await asyncio.to_thread(self.cycle_measures, cycle, end_s, observer.t0, tracks, patrols, region, samples)
        self.cycles.append(cycle)

    def cycle_measures(self, cycle: dict, end_s: float, t0: float, tracks: dict, patrols: dict, region,
                       samples: list[dict]) -> None:
        """Fill in `cycle`'s measures (pure: runs off the event loop)."""
        tracks = {n: [(p[0] - t0, p[1], p[2]) for p in track] for n, track in tracks.items()}
        manned = manned_at(tracks, patrols, cycle["push_s"], CAPTURE)
        cycle["patrols"] = {n: np.round(np.asarray(p), 0).tolist() for n, p in patrols.items()}
        cycle["manned_by"] = manned
        done = [t for t in manned.values() if t is not None]
        cycle["all_manned_s"] = round(max(done) - cycle["push_s"], 1) if len(done) == len(manned) and done else None
        spill = self.truth.at(end_s)
        patrol_from = cycle["oil_path_s"]
        window = [s for s in samples if patrol_from <= s["mission_s"] <= end_s]
        cycle["coverage_mean"] = round(float(np.mean([s["coverage"] for s in window])), 4) if window else None
        cycle["end_s"] = round(end_s, 1)
        if region is not None:
            gap, where = largest_revisit_gap(region, tracks, patrol_from, end_s, self.reach, spacing=250.0, step=30.0)
            cycle["revisit_gap_s"], cycle["revisit_gap_at"] = round(gap, 0), [round(v) for v in where]
            cycle["oil_inside"] = round(oil_containment(spill, region).share_inside, 4)
            cycle["region"] = np.round(np.asarray(region), 0).tolist()
        cycle["offsets"] = {n: {k: round(v, 3 if k == "over_oil" else 0) for k, v in vars(o).items()}
                            for n, o in patrol_offsets(spill, patrols, spacing=200.0).items()}
        cycle["truth_end"] = geometry_rings(spill)


def transit_bound(observer: Observer, plan_s: float, top_speed: float) -> tuple[float, float]:
    """The longest route to a starting position, from where the vehicle was at the plan (m), and the
    physical bound on manning: that length / top speed × BOUND_FACTOR (s)."""
    where = positions_at(observer.tracks, observer.t0 + plan_s, stale=60.0)
    longest = 0.0
    for name, route in observer.routes.items():
        if name in where and route:
            legs = np.vstack([where[name], np.asarray(route, float)])
            longest = max(longest, float(np.hypot(*np.diff(legs, axis=0).T).sum()))
    return longest, longest / top_speed * BOUND_FACTOR


async def run_cycle(run: ResponseRun, forecast: CycleForecast, pusher: BoundaryPusher, mission: OilspillMission,
                    timeout: float) -> dict:
    """Push one forecast cycle at its mission time and follow the fleet until every arc is manned."""
    observer = run.observer
    await wait_for(lambda: run.mission_s() >= forecast.push_s, timeout, f"cycle {forecast.number}: its push time",
                   mission, progress=lambda: observer.say("waiting", f"cycle {forecast.number} at mission hour "
                                                                     f"{forecast.push_s / 3600:g}"), every=30.0)
    index = len(observer.events)
    pushed = observer.note("push", f"cycle {forecast.number}: forecast from scenario hour {forecast.issued_hour:g}, "
                                   f"{len(forecast.lines)} horizons")
    for line in forecast.lines:
        await pusher.push(line)
    await wait_for(lambda: observer.phase_event(OIL_PATH, index) is not None, timeout,
                   f"cycle {forecast.number}: every arc manned ({OIL_PATH})", mission,
                   progress=lambda: observer.say("transit", f"{len(patrolling(observer))} of "
                                                            f"{len(mission.fleet)} on their arcs"), every=15.0)
    manned_index = observer.phase_event(OIL_PATH, index)
    marks = {OIL_PATH: observer.events[manned_index]["moos_s"]}
    earlier = pushed["moos_s"]
    for phase in (STATION_KEEPING, STARTING_POSITION):   # a change missed while the observer reconnected:
        found = observer.phase_event(phase, index)          # the mark before it stands in
        marks[phase] = earlier = observer.events[found]["moos_s"] if found is not None and found < manned_index \
            else earlier
    longest, bound = transit_bound(observer, marks[STARTING_POSITION], TOP_SPEED)
    horizon = status_horizon(observer.status)
    manned = marks[OIL_PATH] - pushed["moos_s"]
    observer.note("manned", f"cycle {forecast.number}: every arc manned {manned:.0f} s after the push "
                            f"(bound {bound:.0f} s = longest route {longest / 1000:.1f} km / {TOP_SPEED:g} m/s "
                            f"x {BOUND_FACTOR}); aiming at the {horizon:g} h forecast")
    return {"cycle": forecast.number, "push_s": pushed["moos_s"], "issued_hour": forecast.issued_hour,
            "horizon_h": horizon, "station_keeping_s": marks[STATION_KEEPING],
            "starting_position_s": marks[STARTING_POSITION], "oil_path_s": marks[OIL_PATH],
            "push_to_manned_s": round(manned, 1), "longest_route_m": round(longest), "bound_s": round(bound, 1),
            "forecasts": {f"{h:g}": {"polygon": np.round(np.asarray(v["polygon"]), 0).tolist(),
                                     "uncertainty_m": round(v["uncertainty_m"]), "valid_hour": v["valid_hour"]}
                          for h, v in forecast.horizons.items()},
            "skill": forecast_skill(run.truth, forecast.horizons),
            "truth_push": geometry_rings(run.truth.at(pushed["moos_s"]))}


def mission_defines(truth: Truth) -> dict[str, str]:
    """The nsplug macros of the response mission: real-scale truth, vessel speeds, arcs."""
    return {"TRUTH": "true", "OIL_SCENARIO": truth.scenario.scenario_id, "OIL_START_HOUR": f"{truth.start_hour:g}",
            "OIL_MAP_SCALE": "1", "SENSOR_RANGE": "500", "TRANSIT_SPEED": f"{TOP_SPEED:g}",
            "LOOP_SPEED": f"{LOOP_SPEED:g}", "PATROL": "arcs", "ARRIVAL_TIMEOUT": "7200", "CAPTURE_RADIUS": "50",
            "SIM_TICK": "4", "HELM_TICK": "2"}


async def run_response(out: Path, vehicles: int, warp: float, cycles: int, cycle_h: float, timeout: float,
                       weights: Path | None = None, kind: str = DEFAULT_MODEL, reach: float = REACH,
                       viewer_port: int | None = None, vessels_per_process: int = 1) -> dict:
    from oilspill_moos.viewer.app import viewer_beside

    truth = load_truth()
    planned = forecast_cycles(truth, cycles, cycle_h, weights, kind)
    nearest = planned[0].horizons[min(planned[0].horizons)]["polygon"]
    mission = OilspillMission(out / "run", vehicles=vehicles, warp=warp, standoff=STANDOFF, node_timeout=120.0,
                              starts=stations(nearest, vehicles, 2000.0), operating_radius=0.0,
                              extra=mission_defines(truth), vessels_per_process=vessels_per_process)
    end_s = cycles * cycle_h * 3600.0
    step_timeout = max(timeout, 1.5 * cycle_h * 3600.0 / warp)
    record: dict = {"scenario": truth.scenario.scenario_id, "start_hour": truth.start_hour, "vehicles": vehicles,
                    "warp": warp, "cycle_h": cycle_h, "reach_m": reach, "standoff_m": STANDOFF,
                    "top_speed": TOP_SPEED, "loop_speed": LOOP_SPEED, "bound_factor": BOUND_FACTOR,
                    "vessels_per_process": vessels_per_process}
    started = time.monotonic()
    with mission, viewer_beside(mission.folder / mission.shoreside.moos_file, viewer_port):
        observer = Observer("127.0.0.1", mission.shoreside.moos_port, warp)
        run = ResponseRun(truth, observer, reach)
        client_task = asyncio.create_task(observer.client.run())
        ticks = TickWatch(mission.communities, warp)
        sampler = None
        try:
            await observer.client.wait_connected(timeout)
            observer.note("start", f"{vehicles} vessels, time warp {warp:g}, truth {truth.scenario.scenario_id} from "
                                   f"hour {truth.start_hour:g}, {cycles} forecast cycles {cycle_h:g} h apart")
            await wait_for(lambda: observer.vehicles_seen() >= set(mission.fleet), timeout,
                           "every vehicle's NODE_REPORT on the shoreside", mission)
            await observer.deploy(mission.fleet, timeout, mission)
            ticks.start()                                 # AppTicks missed count from here
            observer.t0 = observer.client.moos_time()     # mission second 0: the truth's START_HOUR
            observer.client.notify("UFLDOILSENSOR_CMD", f"hour={truth.start_hour:g}")
            observer.note("deployed", f"{':'.join(mission.fleet)}; truth at scenario hour {truth.start_hour:g}")
            sampler = asyncio.create_task(run.sampler(60.0))
            pusher = BoundaryPusher("127.0.0.1", mission.boundary_port, connect_timeout=timeout)
            for k, forecast in enumerate(planned):
                cycle = await run_cycle(run, forecast, pusher, mission, step_timeout)
                cycle_end = planned[k + 1].push_s if k + 1 < len(planned) else end_s
                await wait_for(lambda: run.mission_s() >= cycle_end, step_timeout, f"cycle {forecast.number}: patrol",
                               mission, every=1e9)
                await run.close_cycle(cycle, run.mission_s())
                say_cycle(observer, run.cycles[-1])
            await pusher.close()
        finally:
            if sampler is not None:
                sampler.cancel()
            observer.client.close()
            client_task.cancel()
            await ticks.close()
    record.update(cycles=run.cycles, samples=run.samples, events=observer.events,
                  wall_s=round(time.monotonic() - started, 1),
                  tracks={n: [[round(t - observer.t0, 1), round(x), round(y)] for t, x, y in track[::10]]
                          for n, track in observer.tracks.items()},
                  node_report_rate=report_rates(observer), behind=ticks.behind())
    return record


def report_rates(observer: Observer) -> dict[str, float]:
    """NODE_REPORTs per mission second per vessel (pNodeReporter's AppTick is 2 in the real-scale
    mission): less means its community fell behind the warped clock."""
    rates = {}
    for name, track in observer.tracks.items():
        if len(track) > 10:
            rates[name] = round((len(track) - 1) / (track[-1][0] - track[0][0]), 3)
    return rates


def say_cycle(observer: Observer, c: dict) -> None:
    manned = "not every arc manned" if c["all_manned_s"] is None else f"every arc manned after {c['all_manned_s']:.0f} s"
    coverage = "n/a" if c["coverage_mean"] is None else f"{100 * c['coverage_mean']:.0f} %"
    observer.note("cycle", f"{c['cycle']}: {manned} (bound {c['bound_s']:.0f} s), perimeter coverage {coverage}, "
                           f"largest revisit gap {c.get('revisit_gap_s', float('nan')) / 60:.0f} min, true oil inside "
                           f"the loop {100 * c.get('oil_inside', float('nan')):.0f} %, forecast IoU "
                           + ", ".join(f"{h} h {s['iou']:.2f}" for h, s in c["skill"].items()))


def summary_lines(record: dict) -> list[str]:
    """The end-of-run summary: per cycle manning vs bound, coverage, gap, oil inside, skill."""
    lines = [f"{record['vehicles']} vessels, {len(record['cycles'])} cycles over "
             f"{record['cycles'][-1]['end_s'] / 3600:.1f} mission hours in {record['wall_s']:.0f} s wall "
             f"(time warp {record['warp']:g})"]
    for c in record["cycles"]:
        within = c["push_to_manned_s"] <= c["bound_s"]
        flown = c["skill"].get(f"{c['horizon_h']:g}", {}).get("iou", float("nan"))
        lines.append(f"cycle {c['cycle']}: push -> every arc manned {c['push_to_manned_s']:.0f} s "
                     f"({'within' if within else 'OVER'} the bound {c['bound_s']:.0f} s); coverage "
                     f"{100 * (c['coverage_mean'] or 0):.0f} %; largest revisit gap "
                     f"{c.get('revisit_gap_s', 0) / 60:.0f} min; oil inside {100 * c.get('oil_inside', 0):.0f} %; "
                     f"{c['horizon_h']:g} h forecast flown, IoU {flown:.2f}")
    rates = record.get("node_report_rate") or {}
    if rates:
        lines.append(f"NODE_REPORTs per mission second: {min(rates.values()):.2f}-{max(rates.values()):.2f} "
                     "(2 expected: below means a community fell behind the warp)")
    if "behind" in record:
        lines.append(behind_line(record["behind"]))
    return lines


def behind_line(behind: list[dict]) -> str:
    """The apps that fell behind their AppTick (TickWatch.behind), by community."""
    apps: dict[str, list[str]] = {}
    for b in behind:
        apps.setdefault(b["community"], []).append(f"{b['app']} ({100 * b['missed'] / b['due']:.0f} % ticks missed)")
    return "apps behind their AppTick: " + ("; ".join(f"{c}: {', '.join(a)}" for c, a in apps.items()) or "none")
