"""What `make demo` leaves and says: a folder per run with `latest` naming the newest, a progress line
while the vessels transit (metres to go along their routes, ETA in mission time), the forecast horizon
as a number, and tracks.png with tick labels that do not run into each other."""
import asyncio
import json
import math
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from oilspill_moos.demo import draw_tracks, new_run_folder, status_horizon, transit_line, write_report
from oilspill_moos.oilspill_mission import Observer, wait_for


def test_each_run_gets_its_own_folder_and_latest_names_the_newest(tmp_path):
    base = tmp_path / "demo-output"
    first = new_run_folder(base, "2026-12-01T22-00-00Z")
    (first / "tracks.png").write_bytes(b"old run")
    second = new_run_folder(base, "2026-12-01T22-00-00Z")     # same second: a suffix, not a shared folder
    third = new_run_folder(base)
    assert second.name == "2026-12-01T22-00-00Z-2" and third != second and not list(second.iterdir())
    assert (base / "latest").resolve() == third.resolve()
    assert (base / "latest").readlink().name == third.name       # relative: the folder can be moved
    assert sorted(p.name for p in base.iterdir()) == sorted([first.name, second.name, third.name, "latest"])


def test_the_horizon_is_a_number():
    assert status_horizon("phase=OIL-PATH,cycle=1,horizon=3,boundary_age=2.5") == 3.0
    assert status_horizon("phase=OIL-PATH,horizon=7.5") == 7.5
    assert status_horizon("phase=STATION-KEEPING,horizon=-1") is None    # pPathAssign: no forecast yet
    assert status_horizon("phase=IDLE") is None and status_horizon("horizon=oops") is None
    assert json.loads(json.dumps({"horizon_h": status_horizon("horizon=3")})) == {"horizon_h": 3}


def test_transit_line_gives_distance_along_the_route_and_the_eta_of_the_last_vehicle():
    routes = {"abe": [(0.0, 0.0), (100.0, 0.0), (100.0, 100.0)], "ben": [(0.0, 0.0), (0.0, 50.0)]}
    positions = {"abe": (50.0, 0.0), "ben": (0.0, 20.0)}
    line = transit_line(positions, routes, {"abe": 2.0, "ben": 2.0}, set())
    assert line == "150 m to go (abe farthest; 0 of 2 at their starting positions), ETA 75 s mission time"
    stopped = transit_line(positions, routes, {"abe": 0.0, "ben": 2.0}, set())
    assert stopped.endswith("ETA unknown (a vehicle is stopped)")
    # ben holds station 15 m off its point (the helm says STATION-KEEPING): arrived, its 0 m/s is no worry
    there = {"abe": (50.0, 0.0), "ben": (0.0, 35.0)}
    assert transit_line(there, routes, {"abe": 2.0, "ben": 0.0}, {"ben"}) == (
        "150 m to go (abe farthest; 1 of 2 at their starting positions), ETA 75 s mission time")
    assert transit_line(there, routes, {"abe": 0.0, "ben": 0.0}, {"abe", "ben"}) == "2 of 2 at their starting positions"
    assert transit_line(positions, {}, {}, set()) is None           # no routes yet: nothing to say
    off_route = transit_line({"abe": (50.0, 30.0)}, {"abe": routes["abe"]}, {"abe": 1.0}, set())
    assert off_route.startswith("180 m to go")                    # 30 m back to the route, then 150 m along it
    single = transit_line({"abe": (0.0, 0.0)}, {"abe": [(30.0, 40.0)]}, {"abe": 5.0}, set())
    assert single.startswith("50 m to go") and "ETA 10 s" in single   # a one-point route: straight there


@given(st.floats(-5e4, 5e4), st.floats(-5e4, 5e4), st.floats(0.5, 10.0))
def test_transit_line_from_the_start_of_a_straight_route_is_its_length(x, y, speed):
    line = transit_line({"abe": (0.0, 0.0)}, {"abe": [(0.0, 0.0), (x, y)]}, {"abe": speed}, set())
    length = math.hypot(x, y)
    assert line.startswith(f"{length:.0f} m to go") and f"ETA {length / speed:.0f} s" in line


def test_a_long_wait_says_how_it_is_going():
    said, start = [], time.monotonic()
    asyncio.run(wait_for(lambda: time.monotonic() - start > 0.35, 5.0, "a slow thing",
                         progress=lambda: said.append(time.monotonic()), every=0.1))
    assert 2 <= len(said) <= 4
    with pytest.raises(TimeoutError, match="a slow thing"):
        asyncio.run(wait_for(lambda: False, 0.2, "a slow thing", progress=lambda: None, every=0.05))


def observer_of(tracks: dict) -> Observer:
    """An Observer that never connects, holding tracks as the demo's would."""
    observer = Observer("127.0.0.1", 1, warp=10.0)
    observer.tracks = tracks
    return observer


def tick_overlaps(fig) -> list[tuple[str, str]]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    clashes = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in axis.get_ticklabels()
                     if t.get_visible() and t.get_text()]
            clashes += [(a, b) for i, (a, box) in enumerate(boxes) for b, other in boxes[:i] if box.overlaps(other)]
    return clashes


@pytest.mark.parametrize("span", [300.0, 8000.0, 60000.0])
def test_tracks_png_tick_labels_never_overlap(tmp_path, span):
    """Forecast runs span tens of km (labels like -20000 ran into each other); the shipped outline a few
    hundred metres."""
    track = [(float(i), -span / 2 + span * i / 20, -span / 3 + span * i / 40) for i in range(21)]
    observer = observer_of({"abe": track, "ben": [(t, x + 40, y) for t, x, y in track]})
    report = {"cycles": [{"horizon_h": 3.0}], "events": []}
    fig = draw_tracks(observer, report)
    assert tick_overlaps(fig) == []
    assert len(fig.axes[0].xaxis.get_ticklabels()) >= 3
    unit = "km" if span >= 5000 else "m"
    assert fig.axes[0].get_xlabel() == f"x ({unit} east of LongOrigin)"
    write_report(tmp_path, observer, report)
    assert (tmp_path / "tracks.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((tmp_path / "timeline.json").read_text())["cycles"][0]["horizon_h"] == 3
