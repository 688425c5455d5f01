"""MOOS geometry strings: seglists, generated patterns, polygons and points, as behaviour
parameters write them.

Spec: docs/spec/ivp-helm.md §8; the generated patterns follow MOOS-IvP's geometry library
(XYFormatUtilsSegl, XYFormatUtilsPoly, XYPatternBlock). Point lists, numbers and key=value lists
are read by moosdb_py.formats, so they mean what they mean in every other app. Points are (n, 2)
float arrays of local x/y metres (x east, y north); angles are compass degrees (0 = north,
90 = east) unless a format says otherwise; shapely checks convexity.

Seglist patterns (waypoints): `format=lawnmower` / `lawnmower:`, `format=bowtie`, `zigzag:`.
Polygon patterns: `format=radial` / `radial::` / short `radial:`, `format=ellipse` / `ellipse:`,
`format=wedge` / `piewedge` / `wedge:`, `format=rangewedge` / `rangewedge:`, `format=pylon` /
`pylon:`, `format=oval` / `oval:`. A polygon parameter also takes any point list.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
import shapely

from moosdb_py import formats


class GeometryError(ValueError):
    """A point, seglist, pattern or polygon string that does not parse."""


def fmt_num(v: float, digits: int = 3) -> str:
    """Numbers in behaviour posts and macros: MOOS's doubleToStringX with at most `digits` decimals."""
    return formats.format_number(v, digits)


def format_seglist(points: np.ndarray) -> str:
    """The posted `pts={x,y:...}` form."""
    return formats.format_seglist(points, 3)


def _blankless(text: str) -> str:
    return "".join(text.split())


def _props(text: str) -> dict[str, str]:
    try:
        return formats.parse_pairs(text)
    except formats.FormatError as exc:
        raise GeometryError(str(exc)) from None


def _number(text: str, what: str) -> float:
    try:
        return formats.parse_number(text)
    except formats.FormatError:
        raise GeometryError(f"{what}: '{text}' is not a number") from None


def _required(props: dict[str, str], keys: tuple[str, ...], pattern: str) -> list[float]:
    missing = [k for k in keys if k not in props]
    if missing:
        raise GeometryError(f"{pattern} needs {', '.join(missing)}")
    return [_number(props[k], k) for k in keys]


def project(x, y, heading, dist):
    """The point `dist` from (x, y) on compass `heading` (MOOS's projectPoint); numpy-friendly."""
    a = np.radians(heading)
    return x + np.multiply(dist, np.sin(a)), y + np.multiply(dist, np.cos(a))


def snapped(pts: np.ndarray, snap: float) -> np.ndarray:
    """Coordinates rounded to multiples of `snap` (none when snap <= 0)."""
    return np.round(pts / snap) * snap if snap > 0 else pts


# ---- seglist patterns --------------------------------------------------------------------
def lawnmower(props: dict[str, str]) -> np.ndarray:
    """A back-and-forth survey of a width x height block about (x, y), as MOOS-IvP's XYPatternBlock.

    With `rows=ew` (the default; also `east-west`) width and height swap and `degs` turns by 90,
    so rows run east-west; `rows=ns` (`north-south`) keeps them north-south. Lanes are `swath`
    (or `lane_width`) apart, ceil(width/swath) + 1 of them, centred on the block's axis turned
    `degs` clockwise (a `degs` below 1 counts as 0, as in MOOS-IvP). The entry is the lane end
    nearest (`startx`, `starty`) (default 0,0) among the outer lanes; the path alternates
    direction lane by lane. `snap` (default 0.00001) rounds the vertices.
    """
    if "swath" not in props and "lane_width" in props:
        props = {**props, "swath": props["lane_width"]}
    x, y, width, height, swath = _required(props, ("x", "y", "width", "height", "swath"), "lawnmower")
    degs = _number(props.get("degs", "0"), "degs")
    rows = props.get("rows", "ew").lower()
    if {"north-south": "ns"}.get(rows, rows) != "ns":
        width, height, degs = height, width, degs + 90
    if width <= 0 or height <= 0 or swath <= 0:
        raise GeometryError("lawnmower needs width, height and swath > 0")
    angle = degs if degs >= 1 else 0.0
    lanes = math.trunc(width / swath + 1 + 0.99999)
    offsets = width / 2 - swath * np.arange(lanes)           # left of the axis first (angle - 90)
    cx, cy = project(x, y, angle - 90, offsets)
    ends = np.stack([np.column_stack(project(cx, cy, angle, height / 2)),
                     np.column_stack(project(cx, cy, angle - 180, height / 2))], axis=1)   # lane, end, xy
    start = np.array([_number(props.get("startx", "0"), "startx"), _number(props.get("starty", "0"), "starty")])
    candidates = [ends[0, 0], ends[0, 1], ends[-1, 0], ends[-1, 1]]
    # First of equals wins; distances equal but for floating-point noise count as equal.
    entry = int(np.argmin(np.round([np.hypot(*(c - start)) for c in candidates], 9)))
    if entry >= 2:
        ends = ends[::-1]
    path = [ends[i] if (entry + i) % 2 == 0 else ends[i][::-1] for i in range(lanes)]
    return snapped(np.concatenate(path), _number(props.get("snap", "0.00001"), "snap"))


def bowtie(props: dict[str, str]) -> np.ndarray:
    """A bow-tie of 10 points about (x, y): rows at y ± height/2 with x ± wid1 and x ± wid2, and the
    waist points x ± wid3; the start corner is the quadrant of (startx, starty) seen from the centre
    (north-east when they are not both given), as MOOS-IvP."""
    x, y, height, w1, w2, w3 = _required(props, ("x", "y", "height", "wid1", "wid2", "wid3"), "bowtie")
    top, bottom = y + height / 2, y - height / 2
    p = {1: (x - w2, top), 2: (x - w1, top), 3: (x + w1, top), 4: (x + w2, top), 5: (x - w3, y), 6: (x + w3, y),
         7: (x - w2, bottom), 8: (x - w1, bottom), 9: (x + w1, bottom), 10: (x + w2, bottom)}
    quadrant = "ne"
    if "startx" in props and "starty" in props:
        rel = float(bearing(x, y, _number(props["startx"], "startx"), _number(props["starty"], "starty")))
        quadrant = ("ne", "se", "sw", "nw")[int(rel // 90) % 4]
    order = {"nw": (9, 10, 6, 4, 3, 8, 7, 5, 1, 2), "ne": (8, 7, 5, 1, 2, 9, 10, 6, 4, 3),
             "se": (2, 1, 5, 7, 8, 3, 4, 6, 10, 9), "sw": (3, 4, 6, 10, 9, 2, 1, 5, 7, 8)}[quadrant]
    return np.array([p[i] for i in order], dtype=float)


def zigzag(fields: list[str]) -> np.ndarray:
    """`startx, starty, angle, length, period, amplitude[, snap]`: from the start, points alternately
    `amplitude` left and right of the axis on compass `angle`, at period/4, 3 period/4, ... along it
    (while short of `length`); snap (default 0.0001) rounds the vertices."""
    if len(fields) not in (6, 7):
        raise GeometryError("zigzag needs startx,starty,angle,length,period,amplitude[,snap]")
    sx, sy, angle, length, period, amplitude, *rest = (_number(f, "zigzag field") for f in fields)
    snap = rest[0] if rest else 0.0001
    if period <= 0 or amplitude <= 0 or length <= 0 or snap < 0:
        raise GeometryError("zigzag needs length, period and amplitude > 0 and snap >= 0")
    along = np.arange(period / 4, length, period / 2)
    side = np.where(np.arange(len(along)) % 2 == 0, -90.0, 90.0)
    ax, ay = project(sx, sy, angle, along)
    px, py = project(ax, ay, angle + side, amplitude)
    return snapped(np.vstack([[sx, sy], np.column_stack([px, py])]), snap)


SEGLIST_PATTERNS: dict[str, Callable[[dict[str, str]], np.ndarray]] = {"lawnmower": lawnmower, "bowtie": bowtie}


def parse_seglist(text: str) -> np.ndarray:
    """A point list (standard `pts={...}` or abbreviated `x,y:x,y`) or a generated seglist pattern."""
    s = _blankless(text)
    low = s.lower()
    if low.startswith("zigzag:") or "format=zigzag" in low:
        body = s[7:] if low.startswith("zigzag:") else ",".join(
            f for f in s.split(",") if f.lower() != "format=zigzag")
        return zigzag(body.split(","))
    if low.startswith("lawnmower:"):
        return lawnmower(_props(s[len("lawnmower:"):]))
    for name, build in SEGLIST_PATTERNS.items():
        if f"format={name}" in low:
            return build(_props(s))
    try:
        return np.array(formats.parse_seglist(s), dtype=float)
    except formats.FormatError as exc:
        raise GeometryError(str(exc)) from None


# ---- polygon patterns --------------------------------------------------------------------
def _radial(props: dict[str, str]) -> np.ndarray:
    """`pts` vertices on a circle of `radius` about (x + shiftx, y + shifty), the first at compass
    angle 180/pts."""
    x, y, radius, n = _required(props, ("x", "y", "radius", "pts"), "radial polygon")
    if radius <= 0 or n < 3 or not n.is_integer():
        raise GeometryError("radial polygon needs radius > 0 and an integer pts >= 3")
    x += _number(props.get("shiftx", "0"), "shiftx")
    y += _number(props.get("shifty", "0"), "shifty")
    angles = 360.0 / n * (np.arange(int(n)) + 0.5)
    return snapped(np.column_stack(project(x, y, angles, radius)), _number(props.get("snap", "0"), "snap"))


def _ellipse(props: dict[str, str]) -> np.ndarray:
    """`pts` (>= 4) vertices of an ellipse about (x, y) with axes `major` and `minor` (full lengths),
    the major axis turned `rads` (or `degs`) counter-clockwise from east, as MOOS-IvP."""
    x, y, major, minor, n = _required(props, ("x", "y", "major", "minor", "pts"), "ellipse")
    if major <= 0 or minor <= 0 or n < 4:
        raise GeometryError("ellipse needs major, minor > 0 and pts >= 4")
    if "rads" in props:
        turn = _number(props["rads"], "rads")
    elif "degs" in props:
        turn = math.radians(_number(props["degs"], "degs"))
    else:
        raise GeometryError("ellipse needs degs or rads")
    a = -math.pi + np.arange(int(n)) * (2 * math.pi / int(n))
    px = x + major / 2 * np.cos(a) * math.cos(turn) - minor / 2 * np.sin(a) * math.sin(turn)
    py = y + minor / 2 * np.sin(a) * math.cos(turn) + major / 2 * np.cos(a) * math.sin(turn)
    return snapped(np.column_stack([px, py]), _number(props.get("snap", "0"), "snap"))


def _arc(left: float, right: float, pts: float) -> np.ndarray:
    """Compass angles from `left` clockwise to `right` in `pts` equal steps (both ends included)."""
    left, right = left % 360, right % 360
    if right < left:
        right += 360
    steps = max(int(pts), 1) if right > left else 0
    return np.linspace(left, right, steps + 1)


def _wedge(props: dict[str, str]) -> np.ndarray:
    """A pie wedge: the centre (x, y) and the arc of `range` from compass `lang` clockwise to `rang`."""
    x, y, lang, rang, rng = _required(props, ("x", "y", "lang", "rang", "range"), "wedge")
    angles = _arc(lang, rang, _number(props.get("pts", "0"), "pts"))
    pts = np.vstack([[x, y], np.column_stack(project(x, y, angles, rng))])
    return snapped(pts, _number(props.get("snap", "0"), "snap"))


def _range_wedge(props: dict[str, str]) -> np.ndarray:
    """The band between `range_min` (default 0) and `range_max` from compass `lang` clockwise to `rang`:
    the outer arc out, the inner arc back."""
    x, y, lang, rang, outer = _required(props, ("x", "y", "lang", "rang", "range_max"), "rangewedge")
    inner = _number(props.get("range_min", "0"), "range_min")
    if inner >= outer:
        raise GeometryError("rangewedge needs range_min < range_max")
    angles = _arc(lang, rang, _number(props.get("pts", "0"), "pts"))
    pts = np.vstack([np.column_stack(project(x, y, angles, outer)),
                     np.column_stack(project(x, y, angles[::-1], inner))])
    return snapped(pts, _number(props.get("snap", "0"), "snap"))


def _pylon(props: dict[str, str]) -> np.ndarray:
    """The rectangle around the segment (x1, y1)-(x2, y2), padded `axis_pad` beyond each end and
    `perp_pad` to each side."""
    x1, y1, x2, y2, axis_pad, perp_pad = _required(props, ("x1", "y1", "x2", "y2", "axis_pad", "perp_pad"), "pylon")
    if axis_pad < 0 or perp_pad < 0:
        raise GeometryError("pylon needs axis_pad and perp_pad >= 0")
    rel = float(bearing(x1, y1, x2, y2))
    back, front = project(x1, y1, rel - 180, axis_pad), project(x2, y2, rel, axis_pad)
    pts = [project(*back, rel - 90, perp_pad), project(*back, rel + 90, perp_pad),
           project(*front, rel + 90, perp_pad), project(*front, rel - 90, perp_pad)]
    return snapped(np.array(pts, dtype=float), _number(props.get("snap", "0"), "snap"))


OVAL_ARC_STEP = 15.0   # degrees between an oval's arc vertices (MOOS-IvP draws the polygon at 15 whatever draw_degs says)


def _oval(props: dict[str, str]) -> np.ndarray:
    """A stadium `len` long and 2·`rad` wide about (x, y) (default 0,0), its long axis on compass `ang`
    (default 0): the half circle about the end centre `ang` side, then the one about the other end,
    each from 90 degrees left of its outward axis clockwise to 90 right in 15-degree steps (26
    vertices). `draw_degs` is accepted and, as in MOOS-IvP, does not change the polygon."""
    rad, length = _required(props, ("rad", "len"), "oval")
    if rad <= 0 or length <= 2 * rad:
        raise GeometryError("oval needs rad > 0 and len > 2 * rad")
    x, y, ang = (_number(props.get(k, "0"), k) for k in ("x", "y", "ang"))
    half = (length - 2 * rad) / 2
    steps = np.arange(-90.0, 90.0 + OVAL_ARC_STEP / 2, OVAL_ARC_STEP)
    arcs = [np.column_stack(project(*project(x, y, axis, half), axis + steps, rad)) for axis in (ang, ang + 180)]
    return np.vstack(arcs)


POLYGON_PATTERNS: dict[str, Callable[[dict[str, str]], np.ndarray]] = {
    "radial": _radial, "ellipse": _ellipse, "wedge": _wedge, "piewedge": _wedge, "rangewedge": _range_wedge,
    "pylon": _pylon, "oval": _oval}
POLYGON_PREFIXES = (("radial::", "radial"), ("ellipse::", "ellipse"), ("ellipse:", "ellipse"), ("wedge:", "wedge"),
                    ("piewedge:", "piewedge"), ("rangewedge:", "rangewedge"), ("pylon:", "pylon"), ("oval:", "oval"))


def _short_radial(text: str) -> np.ndarray:
    """`radial: X, Y, R, N[, snap[, label]]`."""
    fields = text.split(",")
    if not 4 <= len(fields) <= 6:
        raise GeometryError(f"short radial form needs X,Y,R,N[,snap[,label]]: '{text}'")
    return _radial(dict(zip(("x", "y", "radius", "pts", "snap"), fields[:5])))


def parse_polygon(text: str) -> np.ndarray:
    """A convex polygon: a generated shape (see the module doc) or a point list."""
    s = _blankless(text)
    low = s.lower()
    prefix = next(((p, name) for p, name in POLYGON_PREFIXES if low.startswith(p)), None)
    if prefix is not None:
        pts = POLYGON_PATTERNS[prefix[1]](_props(s[len(prefix[0]):]))
    elif low.startswith("radial:"):
        pts = _short_radial(s[len("radial:"):])
    elif "format=" in low and not low.startswith("pts={"):
        props = _props(s)
        shape = props.pop("format", "").lower()
        if shape not in POLYGON_PATTERNS:
            raise GeometryError(f"unsupported polygon format '{shape}' in '{text}' (this helm has "
                                f"{', '.join(POLYGON_PATTERNS)})")
        pts = POLYGON_PATTERNS[shape](props)
    else:
        pts = parse_seglist(s)
    if len(pts) >= 3:
        poly = shapely.Polygon(pts)
        if not poly.is_valid or abs(poly.area - poly.convex_hull.area) > 1e-6 * max(poly.area, 1.0):
            raise GeometryError(f"polygon is not convex: '{text}'")
    return pts


def parse_point(text: str) -> tuple[float, float]:
    """`x,y`, `x:y`, `x=1,y=2[,label=..]` or abbreviated `4,5:label,foo`."""
    s = _blankless(text)
    if "=" in s:
        props = _props(s.replace(":", ","))
        x, y = _required(props, ("x", "y"), f"point '{text}'")
        return x, y
    first = s.split(":")
    if len(first) == 2 and "," not in s:
        return _number(first[0], "x"), _number(first[1], "y")
    parts = first[0].split(",")
    if len(parts) < 2:
        raise GeometryError(f"point '{text}' must be x,y")
    return _number(parts[0], "x"), _number(parts[1], "y")


def are_floats(*values) -> bool:
    """Plain numbers, not arrays (numpy's float64 is a float too): single values take plain math."""
    for v in values:      # a loop, not all() over a generator: asked several times every helm iteration
        if not isinstance(v, float):
            return False
    return True


def bearing(x1, y1, x2, y2):
    """Marine bearing in degrees [0,360): 0 = north (+y), 90 = east; numpy-friendly. Plain math for
    four floats: the helm asks for single bearings every iteration, where a ufunc costs 20 times more."""
    if are_floats(x1, y1, x2, y2):
        return math.degrees(math.atan2(x2 - x1, y2 - y1)) % 360.0
    return np.degrees(np.arctan2(np.subtract(x2, x1), np.subtract(y2, y1))) % 360.0


def distance(x1, y1, x2, y2):
    """Euclidean distance; numpy-friendly, plain math for four floats (as `bearing`)."""
    if are_floats(x1, y1, x2, y2):
        return math.hypot(x2 - x1, y2 - y1)
    return np.hypot(np.subtract(x2, x1), np.subtract(y2, y1))
