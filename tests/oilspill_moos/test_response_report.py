"""report.html of a response run, drawn from a hand-built record: every figure there, axes with units,
legends, no two labels on top of each other, and the page opened in a real browser with every image
loaded."""
import asyncio
import html

import numpy as np
import pytest

from browser import Browser, find_chromium
from oilspill_moos.response_demo import summary_lines
from oilspill_moos.response_report import FIGURES, write_response_report


def square(cx, cy, r):
    return [[cx - r, cy - r], [cx + r, cy - r], [cx + r, cy + r], [cx - r, cy + r]]


def hand_built_record() -> dict:
    """Two cycles, a 6 km square spill drifting north-east, four vessels on arcs of a loop 1 km out."""
    cycles = []
    for k in range(2):
        push, end = k * 7200.0, (k + 1) * 7200.0
        region = square(1000 * k, 1000 * k, 4000)
        patrols = {name: [region[i], region[(i + 1) % 4]] for i, name in enumerate(("abe", "ben", "cal", "deb"))}
        cycles.append({
            "cycle": k + 1, "push_s": push, "issued_hour": 17 + 2 * k, "horizon_h": 3.0,
            "station_keeping_s": push + 1, "starting_position_s": push + 30, "oil_path_s": push + 1500,
            "end_s": end, "push_to_manned_s": 1500.0, "bound_s": 1700.0, "longest_route_m": 5000,
            "forecasts": {f"{h:g}": {"polygon": square(1000 * k + 300 * h / 3, 1000 * k, 3000 + 100 * h),
                                     "uncertainty_m": 200 * h, "valid_hour": 17 + 2 * k + h} for h in (3, 7, 11, 15)},
            "skill": {f"{h:g}": {"iou": round(0.8 - 0.04 * h, 2), "centroid_error_km": 0.2 * h,
                                 "valid_hour": 17 + 2 * k + h} for h in (3, 7, 11, 15)},
            "truth_push": [square(1000 * k, 1000 * k, 3000)], "truth_end": [square(1000 * k + 500, 1000 * k + 500, 3200)],
            "patrols": patrols, "manned_by": {n: push + 1500 for n in patrols}, "all_manned_s": 1500.0,
            "coverage_mean": 0.3 + 0.1 * k, "revisit_gap_s": 3000.0 - 600 * k, "revisit_gap_at": [0, -4000],
            "oil_inside": 0.95, "region": region,
            "offsets": {n: {"median_m": 1000.0 - 300 * i, "nearest_m": 500.0, "farthest_m": 1500.0, "over_oil": 0.0}
                        for i, n in enumerate(patrols)}})
    times = np.arange(0, 14400, 60.0)
    tracks = {name: [[t, 4000 * np.cos(t / 3000 + i), 4000 * np.sin(t / 3000 + i)] for t in times[::5]]
              for i, name in enumerate(("abe", "ben", "cal", "deb"))}
    samples = [{"mission_s": t, "hour": 17 + t / 3600, "patrolling": 4, "coverage": 0.3 + 0.1 * np.sin(t / 2000),
                "oil_inside": 0.95} for t in times]
    return {"scenario": "strong_forcing-2214", "start_hour": 17.0, "vehicles": 4, "warp": 15.0, "cycle_h": 2.0,
            "reach_m": 1000.0, "standoff_m": 500.0, "top_speed": 4.0, "loop_speed": 3.0, "bound_factor": 1.3,
            "cycles": cycles, "samples": samples, "events": [], "wall_s": 600.0, "tracks": tracks,
            "node_report_rate": {"abe": 1.98, "ben": 2.0}}


def text_overlaps(fig) -> list[tuple[str, str]]:
    """Pairs of visible, non-empty texts of the figure (ticks, axis labels, titles, legends) whose boxes meet."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    ticks, drawn = set(), []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            labels = axis.get_ticklabels()
            ticks.update(map(id, labels))   # a label whose tick lies outside the axis is not drawn
            drawn += [label for at, label in zip(axis.get_majorticklocs(), labels) if lo <= at <= hi]
    drawn += [t for t in fig.findobj(Text) if id(t) not in ticks]
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in drawn if t.get_visible() and t.get_text().strip()]
    return [(a, b) for i, (a, box) in enumerate(boxes) for b, other in boxes[:i] if box.overlaps(other)]


@pytest.mark.parametrize("name, draw, caption", FIGURES, ids=[f[0] for f in FIGURES])
def test_every_figure_has_units_legends_and_no_overlapping_labels(name, draw, caption):
    fig = draw(hand_built_record())
    assert text_overlaps(fig) == []
    for ax in fig.axes:
        assert ax.get_xlabel() or ax.get_xticklabels(), name
        assert ax.get_legend() is not None or name == "map.png", f"{name}: {ax.get_title()} has no legend"
        if name != "timeline.png":
            assert "(" in ax.get_ylabel() or "IoU" in ax.get_ylabel(), f"{name}: y axis without a unit"
    if name == "map.png":
        assert all(ax.get_legend() is not None for ax in fig.axes)
        assert all("km" in ax.get_xlabel() for ax in fig.axes)


def test_the_page_shows_the_summary_the_table_and_every_figure(tmp_path):
    record = hand_built_record()
    page = write_response_report(tmp_path, record)
    text = page.read_text()
    for name, _, _ in FIGURES:
        assert f'src="{name}"' in text and (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
    assert "every arc manned 1500 s (within the bound 1700 s)" in text
    assert summary_lines(record)[1].startswith("cycle 1: push -> every arc manned 1500 s")
    assert (tmp_path / "report.json").exists()


def test_the_summary_and_the_page_say_which_apps_fell_behind_their_apptick(tmp_path):
    record = hand_built_record()
    assert not any("AppTick" in line for line in summary_lines(record))    # a record from before the watch
    record["behind"] = []
    assert summary_lines(record)[-1] == "apps behind their AppTick: none"
    record["behind"] = [{"community": "cal", "app": "pLogger", "missed": 8, "due": 100},
                        {"community": "cal", "app": "uSimMarine", "missed": 30, "due": 1000},
                        {"community": "deb", "app": "pHelmIvP", "missed": 5, "due": 50}]
    line = ("apps behind their AppTick: cal: pLogger (8 % ticks missed), uSimMarine (3 % ticks missed); "
            "deb: pHelmIvP (10 % ticks missed)")
    assert summary_lines(record)[-1] == line
    assert f"<li>{html.escape(line)}</li>" in write_response_report(tmp_path, record).read_text()


@pytest.mark.skipif(find_chromium() is None, reason="no chromium on PATH (Debian package `chromium`)")
def test_a_real_browser_opens_the_report_with_every_image_loaded(tmp_path):
    page = write_response_report(tmp_path, hand_built_record())

    async def look():
        async with Browser(1280, 900) as browser:
            await browser.goto(page.as_uri())
            images = await browser.evaluate(
                "[...document.images].map(i => [i.getAttribute('src'), i.complete && i.naturalWidth > 0])")
            rows = await browser.evaluate("document.querySelectorAll('table tbody tr').length")
            summary = await browser.evaluate("document.getElementById('summary').innerText")
            return images, rows, summary

    images, rows, summary = asyncio.run(look())
    assert sorted(src for src, _ in images) == sorted(name for name, _, _ in FIGURES)
    assert all(loaded for _, loaded in images), images
    assert rows == 2 and "4 vessels" in summary
