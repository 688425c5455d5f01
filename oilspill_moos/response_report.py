"""report.html of a response run (oilspill_moos/response_demo.py): the page and the PNGs it shows,
drawn from the run's record (report.json) alone, so a report can be redrawn without the run.

* map.png — per cycle: the truth at the push and at the end of the cycle, the forecast of every
  horizon with its uncertainty contour, the stand-off loop, each vessel's arc and track;
* timeline.png — per cycle: station-keeping, transit and patrol, the manning bound;
* measures.png — perimeter coverage and oil inside the loop over time, manning time against the
  bound, the largest revisit gap, each vessel's patrol offset from the true boundary;
* skill.png — each horizon's forecast against the truth at its valid hour, per cycle.
"""
from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

PHASE_COLOURS = {"station-keeping": "tab:gray", "transit": "tab:orange", "patrol": "tab:green"}
HORIZON_COLOURS = ("#9ecae1", "#4292c6", "#2171b5", "#08306b", "#000000")   # blues, darker further ahead


def vessel_colours(names) -> dict[str, str]:
    """One colour per vessel, the same in every figure, none of them a horizon's blue."""
    from matplotlib import colormaps

    palette = colormaps["Dark2"].colors + colormaps["Set1"].colors[:1] + colormaps["Accent"].colors[4:]
    return {name: palette[i % len(palette)] for i, name in enumerate(sorted(names))}


def km_axes(ax) -> None:
    """Map axes in km east/north of the mission origin, few enough ticks that labels never meet."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    for axis, what in ((ax.xaxis, "x (km east of LongOrigin)"), (ax.yaxis, "y (km north of LatOrigin)")):
        axis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 1000:g}"))
        axis.set_label_text(what)


def _ring(ax, ring, **style):
    xy = np.asarray(ring, float)
    if len(xy):
        xy = np.vstack([xy, xy[:1]])
        return ax.plot(xy[:, 0], xy[:, 1], **style)


def draw_map(record: dict):
    from matplotlib.figure import Figure
    from shapely.geometry import Polygon

    cycles = record["cycles"]
    fig = Figure(figsize=(6.2 * len(cycles), 7.2))
    axes = fig.subplots(1, len(cycles), squeeze=False)[0]
    names = sorted(record["tracks"])
    colours = vessel_colours(names)
    for ax, c in zip(axes, cycles):
        for i, ring in enumerate(c["truth_push"]):
            xy = np.asarray(ring)
            ax.fill(xy[:, 0], xy[:, 1], color="sienna", alpha=0.25, lw=0,
                    label=f"truth at the push (hour {record['start_hour'] + c['push_s'] / 3600:.1f})" if i == 0 else None)
        for i, ring in enumerate(c["truth_end"]):
            _ring(ax, ring, color="sienna", lw=1.5,
                  label=f"truth at the cycle's end (hour {record['start_hour'] + c['end_s'] / 3600:.1f})"
                  if i == 0 else None)
        for j, (horizon, f) in enumerate(sorted(c["forecasts"].items(), key=lambda item: float(item[0]))):
            colour = HORIZON_COLOURS[j % len(HORIZON_COLOURS)]
            flown = float(horizon) == c["horizon_h"]
            _ring(ax, f["polygon"], color=colour, lw=2.0 if flown else 1.0,
                  label=f"{horizon} h forecast{' (flown)' if flown else ''}")
            band = Polygon(f["polygon"]).buffer(f["uncertainty_m"])
            if not band.is_empty and band.geom_type == "Polygon":
                _ring(ax, band.exterior.coords[:-1], color=colour, lw=0.8, ls=":",
                      label=f"{horizon} h + uncertainty ({f['uncertainty_m'] / 1000:.1f} km)")
        if "region" in c:
            _ring(ax, c["region"], color="darkorange", lw=1, ls="--", label="stand-off loop")
        for name in names:
            track = np.asarray([p for p in record["tracks"][name] if c["push_s"] <= p[0] <= c["end_s"]])
            if len(track):
                ax.plot(track[:, 1], track[:, 2], lw=0.6, color=colours[name], alpha=0.8)
            patrol = np.asarray(c["patrols"].get(name, []))
            if len(patrol):
                ax.plot(patrol[:, 0], patrol[:, 1], lw=3.5, color=colours[name], alpha=0.7, label=f"{name} arc")
        ax.set_aspect("equal")
        km_axes(ax)
        ax.set_title(f"cycle {c['cycle']}: mission hours {c['push_s'] / 3600:.1f}-{c['end_s'] / 3600:.1f}")
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=7, frameon=False)
    fig.suptitle("truth, forecasts by horizon (dotted: + uncertainty), stand-off loop, arcs (thick) and tracks (thin)")
    return fig


def draw_timeline(record: dict):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 1.2 + 0.8 * len(record["cycles"])))
    ax = fig.subplots()
    for row, c in enumerate(record["cycles"]):
        spans = (("station-keeping", c["push_s"], c["starting_position_s"]),
                 ("transit", c["starting_position_s"], c["oil_path_s"]),
                 ("patrol", c["oil_path_s"], c["end_s"]))
        for phase, start, end in spans:
            ax.barh(row, (end - start) / 3600, left=start / 3600, color=PHASE_COLOURS[phase], height=0.5,
                    label=phase if row == 0 else None)
        bound = (c["push_s"] + c["bound_s"]) / 3600
        ax.plot([bound, bound], [row - 0.35, row + 0.35], color="black", lw=2,
                label="manning bound (longest route / top speed x 1.3)" if row == 0 else None)
    ax.set_yticks(range(len(record["cycles"])), [f"cycle {c['cycle']}" for c in record["cycles"]])
    ax.invert_yaxis()
    ax.set_xlabel("mission time (h)")
    ax.set_title("forecast cycles and fleet phases")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.35 if len(record["cycles"]) < 3 else -0.25), ncol=4,
              fontsize=8, frameon=False)
    return fig


def draw_measures(record: dict):
    from matplotlib.figure import Figure

    cycles = record["cycles"]
    fig = Figure(figsize=(12, 8.5))
    (cover, manning), (gaps, offsets) = fig.subplots(2, 2)
    samples = record["samples"]
    hours = [s["mission_s"] / 3600 for s in samples]
    cover.plot(hours, [100 * s["coverage"] for s in samples], color="tab:green",
               label=f"true perimeter within {record['reach_m'] / 1000:g} km of a patrolling vessel")
    cover.plot(hours, [100 * s["oil_inside"] if "oil_inside" in s else np.nan for s in samples], color="sienna",
               label="true oil inside the stand-off loop")
    for i, c in enumerate(cycles):
        cover.axvline(c["push_s"] / 3600, color="grey", ls=":", label="forecast push" if i == 0 else None)
    cover.set_xlabel("mission time (h)")
    cover.set_ylabel("share (%)")
    cover.set_ylim(0, 105)
    cover.set_title("coverage and containment over time")
    cover.legend(loc="center right", fontsize=7)
    x = np.arange(len(cycles))
    labels = [f"cycle {c['cycle']}" for c in cycles]
    manning.bar(x - 0.2, [c["push_to_manned_s"] / 60 for c in cycles], 0.4, color="tab:orange",
                label="push -> every arc manned")
    manning.bar(x + 0.2, [c["bound_s"] / 60 for c in cycles], 0.4, color="lightgrey", edgecolor="black",
                label="bound: longest route / top speed x 1.3")
    manning.set_xticks(x, labels)
    manning.set_ylabel("minutes (mission time)")
    manning.set_title("time to man every arc after a push")
    manning.legend(loc="best", fontsize=7)
    gaps.bar(x, [c.get("revisit_gap_s", 0) / 60 for c in cycles], 0.5, color="tab:blue",
             label=f"longest stretch without a vessel within {record['reach_m'] / 1000:g} km")
    gaps.set_xticks(x, labels)
    gaps.set_ylabel("minutes (mission time)")
    gaps.set_title("largest revisit gap along the stand-off loop (while patrolling)")
    gaps.legend(loc="best", fontsize=7)
    names = sorted({n for c in cycles for n in c["offsets"]})
    colours = vessel_colours(record["tracks"] or names)
    width = 0.8 / max(len(names), 1)
    for k, name in enumerate(names):
        values = [c["offsets"].get(name, {}).get("median_m", np.nan) / 1000 for c in cycles]
        offsets.bar(x - 0.4 + width * (k + 0.5), values, width, color=colours.get(name, "grey"), label=name)
    offsets.axhline(0, color="black", lw=0.8)
    offsets.set_xticks(x, labels)
    offsets.set_ylabel("km (negative: over oil)")
    offsets.set_title("patrol's median distance outside the true boundary")
    offsets.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=min(len(names), 6), fontsize=7,
                   frameon=False)
    fig.subplots_adjust(hspace=0.45, wspace=0.25)
    return fig


def draw_skill(record: dict):
    from matplotlib.figure import Figure

    cycles = record["cycles"]
    fig = Figure(figsize=(11, 4.2), layout="constrained")
    iou, error = fig.subplots(1, 2)
    horizons = sorted({h for c in cycles for h in c["skill"]}, key=float)
    x = np.arange(len(cycles))
    width = 0.8 / max(len(horizons), 1)
    for j, horizon in enumerate(horizons):
        colour = HORIZON_COLOURS[j % len(HORIZON_COLOURS)]
        offset = -0.4 + width * (j + 0.5)
        iou.bar(x + offset, [c["skill"].get(horizon, {}).get("iou", np.nan) for c in cycles], width, color=colour,
                label=f"{horizon} h")
        error.bar(x + offset, [c["skill"].get(horizon, {}).get("centroid_error_km", np.nan) for c in cycles], width,
                  color=colour, label=f"{horizon} h")
    for ax, what, title in ((iou, "IoU with the truth", "overlap with the truth at the valid hour"),
                            (error, "centroid error (km)", "centroid distance from the truth")):
        ax.set_xticks(x, [f"cycle {c['cycle']}" for c in cycles])
        ax.set_ylabel(what)
        ax.set_title(title)
        ax.legend(title="horizon", fontsize=7, loc="best")
    iou.set_ylim(0, 1.15)
    fig.suptitle("forecast skill per cycle")
    return fig


FIGURES = (("map.png", draw_map, "The truth (brown) at each push and at the end of the cycle, the forecast of "
            "every horizon with its uncertainty contour, the stand-off loop, each vessel's arc and its track."),
           ("timeline.png", draw_timeline, "Forecast cycles and the fleet's phases on the mission clock; the black "
            "mark is the physical bound on manning every arc."),
           ("measures.png", draw_measures, "The measures a responder reads: coverage of the true perimeter and "
            "oil inside the loop over time; manning time against the bound; the largest revisit gap; each "
            "vessel's patrol against the true boundary."),
           ("skill.png", draw_skill, "Each horizon's forecast against the truth at its valid hour."))


def _table(record: dict) -> str:
    head = ("cycle", "horizon flown (h)", "push → every arc manned (s)", "bound (s)", "coverage", "largest revisit "
            "gap (min)", "true oil inside the loop", "IoU of the flown forecast")
    rows = []
    for c in record["cycles"]:
        flown = c["skill"].get(f"{c['horizon_h']:g}", {}).get("iou")
        cells = (c["cycle"], f"{c['horizon_h']:g}", f"{c['push_to_manned_s']:.0f}", f"{c['bound_s']:.0f}",
                 "–" if c["coverage_mean"] is None else f"{100 * c['coverage_mean']:.0f} %",
                 f"{c.get('revisit_gap_s', 0) / 60:.0f}", f"{100 * c.get('oil_inside', 0):.0f} %",
                 "–" if flown is None else f"{flown:.2f}")
        rows.append("<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in cells) + "</tr>")
    return ("<table><thead><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr></thead><tbody>"
            + "".join(rows) + "</tbody></table>")


def write_response_report(out: Path, record: dict) -> Path:
    """report.json, the PNGs and report.html in `out`; returns the page's path."""
    from oilspill_moos.response_demo import summary_lines

    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(record))
    sections = []
    for name, draw, caption in FIGURES:
        fig = draw(record)
        fig.savefig(out / name, dpi=90, bbox_inches="tight")
        sections.append(f'<figure id="{name[:-4]}"><img src="{name}" alt="{html.escape(caption)}">'
                        f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    summary = "".join(f"<li>{html.escape(line)}</li>" for line in summary_lines(record))
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>oil-spill response: {html.escape(record['scenario'])}</title>
<style>body{{font-family:sans-serif;max-width:1400px;margin:1em auto;padding:0 1em}}
img{{max-width:100%}}table{{border-collapse:collapse}}td,th{{border:1px solid #999;padding:.2em .5em}}
figcaption{{color:#444;margin-bottom:2em}}</style></head>
<body><h1>Oil-spill response against a truth spill</h1>
<p>Truth: held-out scenario <b>{html.escape(record['scenario'])}</b> from hour {record['start_hour']:g} at real
scale; {record['vehicles']} vessels ({record['top_speed']:g} m/s transit, {record['loop_speed']:g} m/s on their
arcs), stand-off {record['standoff_m']:g} m, a forecast cycle every {record['cycle_h']:g} mission hours; time warp
{record['warp']:g}.</p>
<ul id="summary">{summary}</ul>
{_table(record)}
{''.join(sections)}
</body></html>
"""
    path = out / "report.html"
    path.write_text(page)
    return path
