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

from .behavior import parse_bool, parse_number
from .bhv_waypoint import BHV_Waypoint
from .geometry import GeometryError, distance, format_seglist, parse_point, parse_polygon
from .ivp_function import IvPFunction

SHARED_WITH_WAYPOINT = {"post_suffix", "speed", "speed_alt", "use_alt_speed", "capture_radius", "radius", "slip_radius",
                        "nm_radius", "ipf_type", "ipf-type", "crs_spd_zaic_ratio", "patience", "visual_hints"}


class BHV_Loiter(BHV_Waypoint):
    type_name = "BHV_Loiter"
    default_name = "loiter"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.base_polygon = np.zeros((0, 2))
        self.clockwise = "true"
        self.acquire_dist = 10.0
        self.center_activate = False
        self.acquiring = False
        self.endless = True
        self.status_var, self.index_var, self.cycle_var = "LOITER_REPORT", "LOITER_INDEX", "LOITER_CYCLES"

    def set_param(self, key: str, value: str) -> bool:
        low = value.strip().lower()
        try:
            if key == "polygon":
                self.base_polygon = parse_polygon(value)
                if len(self.base_polygon) < 3:
                    raise ValueError("loiter polygon needs at least 3 vertices")
                self._order_vertices()
            elif key == "clockwise":
                if low not in ("true", "false", "best"):
                    raise ValueError("clockwise must be true, false or best")
                self.clockwise = low
                self._order_vertices()
            elif key == "acquire_dist":
                self.acquire_dist = parse_number(value, key, 0)
            elif key == "center_activate":
                self.center_activate = parse_bool(value, key)
            elif key in ("center_assign", "xcenter_assign", "ycenter_assign"):
                self._assign_center(key, low)
            elif key in SHARED_WITH_WAYPOINT:
                return super().set_param(key, value)
            else:
                return False
        except GeometryError as exc:
            raise ValueError(str(exc)) from None
        return True

    def _assign_center(self, key: str, value: str) -> None:
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
