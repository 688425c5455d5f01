"""BHV_Loiter: circle a convex polygon's vertices for ever, acquiring it from outside first.

Our own reading of the reference: the vertices are visited in the chosen direction with the
Waypoint advance rules (capture and slip radius) and the Waypoint objective function; when
ownship is farther than `acquire_dist` outside the polygon, the nearest vertex becomes the
target again (LOITER_ACQUIRE = 1). `center_activate` moves the polygon onto ownship each time
the behaviour starts running.
"""
from __future__ import annotations

import numpy as np
import shapely

from .bhv_waypoint import BHV_Waypoint
from .geometry import distance, format_seglist, parse_point, parse_polygon
from .ivp_function import IvPFunction
from .parameters import BOOLEAN, NON_NEGATIVE, Parser, attr, one_of, param, parse_number

SHARED_WITH_WAYPOINT = ("post_suffix", "speed", "speed_alt", "use_alt_speed", "capture_radius", "radius", "slip_radius",
                        "nm_radius", "ipf_type", "ipf-type", "crs_spd_zaic_ratio", "patience", "visual_hints",
                        "cycleflag", "wptflag")


class BHV_Loiter(BHV_Waypoint, inherit=SHARED_WITH_WAYPOINT):
    type_name = "BHV_Loiter"
    default_name = "loiter"
    params = (
        attr("acquire_dist", "acquire_dist", NON_NEGATIVE, "10",
             "farther than this outside the polygon, the nearest vertex becomes the target again"),
        attr("center_activate", "center_activate", BOOLEAN, "false",
             "move the polygon onto ownship each time the behaviour starts running"),
    )

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.base_polygon = np.zeros((0, 2))
        self.clockwise = "true"
        self.acquiring = False
        self.endless = True
        self.status_var, self.index_var, self.cycle_var = "LOITER_REPORT", "LOITER_INDEX", "LOITER_CYCLES"

    @param("polygon", parse=Parser("convex polygon", lambda value, key: parse_polygon(value)),
           doc="the vertices to circle (radial forms included), at least 3")
    def _set_polygon(self, pts: np.ndarray) -> None:
        if len(pts) < 3:
            raise ValueError("loiter polygon needs at least 3 vertices")
        self.base_polygon = pts
        self._order_vertices()

    @param("clockwise", parse=one_of("true", "false", "best"), default="true",
           doc="direction of travel; `best`: the one needing the smaller turn from the present heading")
    def _set_clockwise(self, low: str) -> None:
        self.clockwise = low
        self._order_vertices()

    @param("center_assign", "xcenter_assign", "ycenter_assign",
           parse=Parser("x,y \\| present_position \\| number", lambda value, key: (key, value.strip().lower())),
           doc="move the polygon's centre to x,y (or ownship's position); the x/y forms move one coordinate")
    def _assign_center(self, key_value: tuple[str, str]) -> None:
        key, value = key_value
        if not len(self.base_polygon):
            raise ValueError(f"{key} needs a polygon first")
        cx, cy = self.base_polygon.mean(axis=0)
        if key == "center_assign":
            x, y = self._ownship() if value == "present_position" else parse_point(value)
        else:
            number = parse_number(value, key)
            x, y = (number, cy) if key == "xcenter_assign" else (cx, number)
        self.base_polygon = self.base_polygon + (x - cx, y - cy)
        self._order_vertices()

    def _order_vertices(self, heading: float | None = None) -> None:
        if not len(self.base_polygon):
            return
        pts = self.base_polygon
        ccw = shapely.LinearRing(pts).is_ccw
        want_cw = self.clockwise == "true" or (self.clockwise == "best" and self._best_is_cw(heading))
        ordered = pts[::-1].copy() if ccw == want_cw else pts.copy()
        self.set_points(ordered)
        self._enter_at_nearest()

    def _best_is_cw(self, heading: float | None) -> bool:
        """With `clockwise = best`: the direction needing the smaller turn from the present heading."""
        if heading is None:
            return True
        x, y = self._ownship()
        cx, cy = self.base_polygon.mean(axis=0)
        # Circling clockwise about the centre means heading 90 degrees right of the bearing to it.
        to_center = np.degrees(np.arctan2(cx - x, cy - y))
        return abs((to_center - 90 - heading + 180) % 360 - 180) <= abs((to_center + 90 - heading + 180) % 360 - 180)

    def _enter_at_nearest(self) -> None:
        if len(self.points):
            x, y = self._ownship()
            self.ix = int(np.argmin(distance(x, y, self.points[:, 0], self.points[:, 1])))
            self.cpa = None

    def on_idle_to_run(self) -> None:
        if self.center_activate and len(self.base_polygon):
            x, y = self._ownship()
            self.base_polygon = self.base_polygon - self.base_polygon.mean(axis=0) + (x, y)
        self._order_vertices(self.info.number("NAV_HEADING"))

    def on_run_state(self) -> IvPFunction | None:
        nav = self.nav()
        if nav is None or not len(self.points):
            return None
        osx, osy = nav[0], nav[1]
        poly = shapely.Polygon(self.points)
        outside = float(poly.exterior.distance(shapely.Point(osx, osy))) if not poly.contains(
            shapely.Point(osx, osy)) else 0.0
        acquiring = outside > self.acquire_dist
        if acquiring and not self.acquiring:
            self._enter_at_nearest()
        self.acquiring = acquiring
        self.post("LOITER_ACQUIRE", 1.0 if acquiring else 0.0)
        self.post("LOITER_DIST_TO_POLY", round(outside, 1))
        self.post("VIEW_POLYGON", f"{format_seglist(self.points)},label={self.ownship}_{self.name}")
        return super().on_run_state()

    def on_run_to_idle(self) -> None:
        super().on_run_to_idle()
        self.post("VIEW_POLYGON", f"{format_seglist(self.points)},label={self.ownship}_{self.name},active=false")
