"""MOOS geometry strings: seglists, polygons and points, as behaviour parameters write them.

Spec: ivp-helm.md §8. Points are (n, 2) float arrays of local x/y metres; shapely checks
convexity. Output strings use the form the helm posts (`pts={x,y:...}`).
"""
from __future__ import annotations

import math

import numpy as np
import shapely


class GeometryError(ValueError):
    """A point, seglist or polygon string that does not parse."""


def fmt_num(v: float, digits: int = 3) -> str:
    """MOOS's number printing in posts and macros (doubleToStringX): at most `digits` decimals, no
    trailing zeros."""
    if float(v).is_integer():
        return str(int(v))
    text = f"{v:.{digits}f}".rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


def _blankless(text: str) -> str:
    return "".join(text.split())


def _split_props(text: str) -> dict[str, str]:
    props: dict[str, str] = {}
    for item in text.split(","):
        if not item:
            continue
        key, sep, value = item.partition("=")
        if not sep:
            raise GeometryError(f"expected key=value, got '{item}'")
        props[key.lower()] = value
    return props


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise GeometryError(f"{what}: '{text}' is not a number") from None
    if not math.isfinite(value):
        raise GeometryError(f"{what}: '{text}' is not finite")
    return value


def _vertex(item: str) -> tuple[float, float] | None:
    """One `x,y[,z]` or `x=..,y=..` vertex; None for a `label,foo`-style property item."""
    if "=" in item:
        props = _split_props(item)
        if "x" not in props or "y" not in props:
            raise GeometryError(f"vertex '{item}' needs x= and y=")
        return _number(props["x"], "x"), _number(props["y"], "y")
    parts = item.split(",")
    try:
        float(parts[0])
    except ValueError:
        if len(parts) == 1:   # `oops`: neither a vertex nor a `key,value` property (MOOS-IvP rejects the list)
            raise GeometryError(f"vertex '{item}' must be x,y or x,y,z") from None
        return None  # `label,foo` and friends are properties, not vertices
    if len(parts) not in (2, 3):
        raise GeometryError(f"vertex '{item}' must be x,y or x,y,z")
    return _number(parts[0], "x"), _number(parts[1], "y")


def lawnmower(props: dict[str, str]) -> np.ndarray:
    """A back-and-forth survey over a width x height box about (x, y), rotated `degs` clockwise.

    Rows run north-south (`rows=ns`, the default) or east-west (`rows=ew`), `swath` apart,
    starting at corner `start` (tl, tr, bl, br; default tl).
    """
    missing = [k for k in ("x", "y", "width", "height", "swath") if k not in props]
    if missing:
        raise GeometryError(f"lawnmower needs {', '.join(missing)}")
    x, y, width, height, swath = (_number(props[k], k) for k in ("x", "y", "width", "height", "swath"))
    if width <= 0 or height <= 0 or swath <= 0:
        raise GeometryError("lawnmower needs width, height and swath > 0")
    rows, start = props.get("rows", "ns").lower(), props.get("start", "tl").lower()
    if rows not in ("ns", "ew") or start not in ("tl", "tr", "bl", "br"):
        raise GeometryError("lawnmower: rows must be ns or ew, start tl, tr, bl or br")
    across, along = (width, height) if rows == "ns" else (height, width)
    offsets = np.arange(0.0, across + 1e-9, swath) - across / 2
    from_right, from_top = start[1] == "r", start[0] == "t"
    if (from_right if rows == "ns" else from_top):
        offsets = -offsets  # first row on the starting side
    ends = np.array([along / 2, -along / 2]) * (1 if (from_top if rows == "ns" else from_right) else -1)
    pts = []
    for i, off in enumerate(offsets):
        for end in (ends if i % 2 == 0 else ends[::-1]):
            pts.append((off, end) if rows == "ns" else (end, off))
    local = np.array(pts)
    a = math.radians(_number(props.get("degs", "0"), "degs"))
    rot = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
    return local @ rot.T + (x, y)


def parse_seglist(text: str) -> np.ndarray:
    """A point list in abbreviated (`x,y:x,y`) or standard (`pts={...}`) form, or a lawnmower pattern."""
    s = _blankless(text)
    low = s.lower()
    if low.startswith("format=lawnmower") or low.startswith("lawnmower:"):
        body = s[len("format=lawnmower"):] if low.startswith("format=") else s[len("lawnmower:"):]
        return lawnmower(_split_props(body.strip(",:")))
    if low.startswith("format=") or low.startswith("radial"):
        raise GeometryError(f"'{text}' is a generated pattern, not a point list")
    if "pts={" in low:
        start = low.index("pts={") + 5
        end = s.find("}", start)
        if end < 0:
            raise GeometryError(f"unclosed 'pts={{' in '{text}'")
        body = s[start:end]
    else:
        body = s
        for prefix in ("pts:", "points:"):
            if low.startswith(prefix):
                body = s[len(prefix):]
    pts = [v for v in (_vertex(item) for item in body.split(":") if item) if v is not None]
    if not pts:
        raise GeometryError(f"no points in '{text}'")
    return np.array(pts, dtype=float)


def _radial(props: dict[str, str]) -> np.ndarray:
    missing = [k for k in ("x", "y", "radius", "pts") if k not in props]
    if missing:
        raise GeometryError(f"radial polygon needs {', '.join(missing)}")
    x, y = _number(props["x"], "x"), _number(props["y"], "y")
    radius, n = _number(props["radius"], "radius"), _number(props["pts"], "pts")
    if radius <= 0 or n < 3 or not n.is_integer():
        raise GeometryError("radial polygon needs radius > 0 and an integer pts >= 3")
    angles = np.radians(360.0 / n * (np.arange(int(n)) + 0.5))
    pts = np.column_stack([x + radius * np.sin(angles), y + radius * np.cos(angles)])
    snap = _number(props.get("snap", "0"), "snap")
    if snap > 0:
        pts = np.round(pts / snap) * snap
    return pts


def parse_polygon(text: str) -> np.ndarray:
    """A convex polygon: radial forms (`format=radial,...`, `radial::...`, `radial: X,Y,R,N`) or a point list."""
    s = _blankless(text)
    low = s.lower()
    if low.startswith("radial::"):
        pts = _radial(_split_props(s[8:]))
    elif low.startswith("radial:"):
        fields = s[7:].split(",")
        if len(fields) < 4:
            raise GeometryError(f"short radial form needs X,Y,R,N: '{text}'")
        keys = ("x", "y", "radius", "pts", "snap", "label")
        pts = _radial(dict(zip(keys, fields)))
    elif low.startswith("format=radial"):
        pts = _radial(_split_props(s[len("format=radial"):].lstrip(",")))
    elif low.startswith("format="):
        raise GeometryError(f"unsupported polygon format in '{text}'")
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
        props = _split_props(s.replace(":", ","))
        if "x" not in props or "y" not in props:
            raise GeometryError(f"point '{text}' needs x= and y=")
        return _number(props["x"], "x"), _number(props["y"], "y")
    first = s.split(":")
    if len(first) == 2 and "," not in s:
        return _number(first[0], "x"), _number(first[1], "y")
    parts = first[0].split(",")
    if len(parts) < 2:
        raise GeometryError(f"point '{text}' must be x,y")
    return _number(parts[0], "x"), _number(parts[1], "y")


def format_seglist(points: np.ndarray) -> str:
    """The posted `pts={x,y:...}` form."""
    return "pts={" + ":".join(f"{fmt_num(x)},{fmt_num(y)}" for x, y in points) + "}"


def bearing(x1, y1, x2, y2):
    """Marine bearing in degrees [0,360): 0 = north (+y), 90 = east; numpy-friendly."""
    return np.degrees(np.arctan2(np.subtract(x2, x1), np.subtract(y2, y1))) % 360.0


def distance(x1, y1, x2, y2):
    return np.hypot(np.subtract(x2, x1), np.subtract(y2, y1))
