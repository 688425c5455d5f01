"""`make demo DEMO_ARGS=--feedback`: the closed loop of issue 9, end to end.

truth spill -> forecast -> fleet -> observations -> corrected forecast -> re-plan, with
missions/oilspill expanded with FEEDBACK (uFldOilSensor, uFldOilFusion, pOilSampler):

1. the forecaster forecasts a held-out scenario from its hours 1-17 (3 h ahead: hour 20);
   uFldOilSensor holds the truth an hour later (the fleet is late);
2. the forecast goes to pPathAssign; the fleet circles it, sampling; the observations reach
   uFldOilFusion, which scores the forecast (OIL_FUSION_SKILL) and writes them for the forecaster;
3. the forecaster re-anchors on them (forecaster/assimilate.py) and forecasts again, 3 h from
   the anchor; the truth clock moves on to that cycle (UFLDOILSENSOR_CMD hour=..);
4. the corrected forecast goes to pPathAssign, which re-plans; the fleet samples again.

The report (feedback.json, feedback.png) sets each forecast, with and without feedback, against
the truth, and shows the live skill score of both cycles.
"""
from __future__ import annotations

import asyncio
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import Polygon

from moosdb_py.client import MOOSClient
from oilspill_moos.oilspill_mission import ORIGIN, Observer, OilspillMission, wait_for
from oilspill_moos.forecaster.assimilate import ingest, read_feedback
from oilspill_moos.forecaster.boundary import outline
from oilspill_moos.forecaster.features import to_plane
from oilspill_moos.forecaster.push import BoundaryPusher
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.response.scenario_map import ScenarioMap
from oilspill_moos.messages import format_points, parse_report
from oilspill_moos.response.path_assign import OIL_PATH

SCENARIO = "strong_forcing-2214"   # held out from the shipped weights' training
MAP_SCALE = 0.015                  # its ~8 km slick becomes ~120 m: a kayak loop of a minute or two
LAST_SATELLITE_H = 17
STANDOFF = 10.0
SENSOR_RANGE = 15.0


def feedback_defines(feedback_file: Path, scenario: str = SCENARIO, start_hour: float = LAST_SATELLITE_H + 4,
                     map_scale: float = MAP_SCALE, sample_interval: float = 3.0) -> dict[str, str]:
    """The nsplug macros that turn missions/oilspill into the closed loop (see feedback.moos)."""
    return {"FEEDBACK": "true", "OIL_SCENARIO": scenario, "OIL_START_HOUR": f"{start_hour:g}",
            "OIL_MAP_SCALE": f"{map_scale:g}", "SENSOR_RANGE": f"{SENSOR_RANGE:g}", "FALSE_POS": "0.02",
            "FALSE_NEG": "0.05", "SAMPLE_INTERVAL": f"{sample_interval:g}", "FEEDBACK_FILE": str(feedback_file)}


def mission_polygon(geometry, world: ScenarioMap) -> Polygon:
    """A forecast (EPSG:4326) as the one-ring outline the forecaster pushes, in mission metres."""
    return world.to_local(Polygon(outline(geometry)))


def boundary_line(polygon: Polygon) -> bytes:
    return f"pts={{{format_points(polygon.exterior.coords[:-1])}}}\n".encode()


def truth_at(scenario, hour: float):
    """The scenario's polygon in force at `hour`, as uFldOilSensor holds it (the latest hourly one)."""
    return scenario.geometries[max(int(np.searchsorted(scenario.times_h, hour, side="right")) - 1, 0)]


def iou(a, b) -> float:
    a, b = to_plane(a), to_plane(b)
    return a.intersection(b).area / a.union(b).area


@dataclass
class FusionWatch:
    """A shoreside client keeping uFldOilFusion's skill reports and warnings."""

    port: int
    warp: float
    skills: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def __post_init__(self):
        self.client = MOOSClient("uFeedbackWatch", "127.0.0.1", self.port, on_mail=self.on_mail,
                                 on_connect=self.on_connect, time_warp=self.warp)

    def on_connect(self) -> None:
        for key in ("OIL_FUSION_SKILL", "OIL_FUSION_WARNING", "OIL_SENSOR_WARNING"):
            self.client.register(key)

    def on_mail(self, mail) -> None:
        for msg in mail:
            (self.skills if msg.key == "OIL_FUSION_SKILL" else self.warnings).append(str(msg.value))

    def last_skill(self, cycle: str) -> dict[str, str]:
        reports = [parse_report(s) for s in self.skills]
        return next((r for r in reversed(reports) if r.get("cycle") == cycle), {})


async def run_feedback_demo(out: Path, vehicles: int, warp: float, loop_time: float, timeout: float) -> dict:
    from oilspill_moos.forecaster.dataset import load_dataset
    from oilspill_moos.forecaster.operational import Forecaster

    forecaster = Forecaster()
    scenario = next(s for s in load_dataset() if s.scenario_id == SCENARIO)
    world = ScenarioMap(LocalGrid(*ORIGIN), MAP_SCALE)
    k = LAST_SATELLITE_H
    history = scenario.geometries[:k], scenario.times()[:k], scenario.environments()[:k]
    satellite_only = forecaster.forecast(*history, scenario.release_time)
    feedback_file = (out / "run" / "oil_feedback.jsonl").resolve()
    feedback_file.unlink(missing_ok=True)
    mission = OilspillMission(out / "run", vehicles=vehicles, warp=warp, standoff=STANDOFF,
                              extra=feedback_defines(feedback_file))
    report: dict = {"scenario": SCENARIO, "map_scale": MAP_SCALE, "vehicles": vehicles, "warp": warp, "cycles": []}
    forecast, valid_h = satellite_only[0].geometry, LAST_SATELLITE_H + satellite_only[0].horizon_h
    drawn: list[dict] = []
    with mission:
        observer = Observer("127.0.0.1", mission.shoreside.moos_port, warp)
        watch = FusionWatch(mission.shoreside.moos_port, warp)
        tasks = [asyncio.create_task(observer.client.run()), asyncio.create_task(watch.client.run())]
        try:
            await observer.client.wait_connected(timeout)
            await wait_for(lambda: observer.vehicles_seen() >= set(mission.fleet), timeout,
                           "every vehicle's NODE_REPORT on the shoreside", mission)
            await observer.deploy(mission.fleet, timeout, mission)
            pusher = BoundaryPusher("127.0.0.1", mission.boundary_port, connect_timeout=timeout)
            for cycle in (1, 2):
                seen_h = valid_h + 1
                if cycle > 1:
                    watch.client.notify("UFLDOILSENSOR_CMD", f"hour={seen_h:g}")
                seq = await pusher.push(boundary_line(mission_polygon(forecast, world)))
                observer.note("push", f"cycle {cycle}: forecast valid at hour {valid_h:g} accepted, seq {seq}")
                await wait_for(lambda: observer.phase_count.get(OIL_PATH, 0) >= cycle, timeout,
                               f"cycle {cycle}: {OIL_PATH}", mission)
                on_loop = observer.moos_now
                await wait_for(lambda: observer.moos_now - on_loop >= loop_time, timeout, f"cycle {cycle}: looping",
                               mission)
                label = f"oilspill_{seq}"
                await wait_for(lambda: watch.last_skill(label), timeout, f"cycle {cycle}: OIL_FUSION_SKILL", mission)
                readings = read_feedback(feedback_file)
                geometries, times, envs = ingest(forecaster, *history, readings, release_time=scenario.release_time)
                truth_seen, truth_valid = truth_at(scenario, seen_h), truth_at(scenario, valid_h)
                without = next(f for f in satellite_only if LAST_SATELLITE_H + f.horizon_h == valid_h)
                entry = {"cycle": cycle, "valid_hour": valid_h, "observed_hour": seen_h,
                         "skill": watch.last_skill(label), "readings_used": len(geometries) > len(history[0]),
                         "iou_forecast_vs_truth": round(iou(forecast, truth_valid), 3),
                         "iou_without_feedback_vs_truth": round(iou(without.geometry, truth_valid), 3),
                         "iou_flown_forecast_at_observation": round(iou(forecast, truth_seen), 3),
                         "iou_reanchored_at_observation": round(iou(geometries[-1], truth_seen), 3)}
                report["cycles"].append(entry)
                recent = readings.recent(history[1][-1], 1.0)
                drawn.append({"truth": world.to_local(truth_seen), "flown": world.to_local(forecast),
                              "anchor": world.to_local(geometries[-1]), "oil": recent.oil,
                              "xy": world.to_local(shapely.MultiPoint(np.column_stack([recent.lon, recent.lat])))})
                observer.note("skill", json.dumps(entry))
                history = geometries, times, envs
                corrected = forecaster.forecast(*history, scenario.release_time)[0]
                forecast, valid_h = corrected.geometry, seen_h + corrected.horizon_h
            await pusher.close()
        finally:
            observer.client.close()
            watch.client.close()
            for task in tasks:
                task.cancel()
    report["warnings"] = watch.warnings[:20]
    report["events"] = observer.events
    out.mkdir(parents=True, exist_ok=True)
    (out / "feedback.json").write_text(json.dumps(report, indent=2))
    draw(out / "feedback.png", drawn, observer.tracks)
    return report


def draw(path: Path, cycles: list[dict], tracks: dict) -> None:
    """Per cycle: the truth the fleet sensed, the forecast it flew, the re-anchored outline, the readings."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    fig, axes = plt.subplots(1, len(cycles), figsize=(7 * len(cycles), 7), squeeze=False)
    for number, (ax, c) in enumerate(zip(axes[0], cycles), start=1):
        for key, style, label in (("truth", dict(color="brown", alpha=0.3), "truth (sensed hour)"),
                                  ("flown", dict(fill=False, ec="black", ls="--"), "forecast flown"),
                                  ("anchor", dict(fill=False, ec="green", lw=2), "re-anchored")):
            for i, part in enumerate(getattr(c[key], "geoms", [c[key]])):
                ax.fill(*part.exterior.xy, **style, label=label if i == 0 else None)
        xy = np.array([p.coords[0] for p in c["xy"].geoms]) if not c["xy"].is_empty else np.empty((0, 2))
        for flag, color, label in ((True, "red", "oil"), (False, "tab:blue", "no oil")):
            ax.plot(*xy[c["oil"] == flag].T, ".", color=color, ms=4, label=label)
        for name, track in sorted(tracks.items()):
            ax.plot([p[1] for p in track], [p[2] for p in track], lw=0.5, color="grey")
        ax.set_aspect("equal")
        ax.set_title(f"cycle {number}")
        ax.legend(loc="upper left", fontsize=7)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)


def main(out: Path, vehicles: int, warp: float, loop_time: float, timeout: float) -> int:
    started = time.monotonic()
    report = asyncio.run(run_feedback_demo(out, vehicles, warp, loop_time, timeout))
    for c in report["cycles"]:
        skill = c["skill"]
        print(f"cycle {c['cycle']}: forecast IoU with the truth {c['iou_forecast_vs_truth']:.3f} "
              f"(satellite only: {c['iou_without_feedback_vs_truth']:.3f}); live skill: agreement "
              f"{skill.get('agreement')}, edge error {skill.get('boundary_error_m')} m; re-anchored on "
              f"{skill.get('observations')} readings: IoU {c['iou_flown_forecast_at_observation']:.3f} -> "
              f"{c['iou_reanchored_at_observation']:.3f}")
    print(f"demo --feedback: done in {time.monotonic() - started:.0f} s; report in {out}/feedback.json")
    return 0
