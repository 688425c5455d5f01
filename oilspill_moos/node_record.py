"""NODE_REPORT and NODE_MESSAGE as the field apps read them, plus the contact geometry they share.

`NodeRecord.parse` reads a node report (field-apps.md section 3.3: `NAME=..,X=..,Y=..,SPD=..,HDG=..`,
keys in any case, LONG for LON, DEPTH for DEP); `NodeMessage.parse` reads a node message
(`src_node=..,dest_node=..,var_name=..,string_val=..|double_val=..`). The contact manager,
uFldNodeComms and uFldCollisionDetect share them, and the CPA and dead-reckoning arithmetic.
"""
from __future__ import annotations

import math
import shlex
from dataclasses import dataclass

from moosdb_py.formats import FormatError, parse_number, parse_pairs


class NodeRecordError(ValueError):
    """A node report or node message that cannot be used; the message quotes it."""


def split_quoted(text: str) -> list[str]:
    """Split at commas outside double quotes, dropping the quotes (`val="a, b"` stays one field)."""
    lexer = shlex.shlex(text, posix=True)
    lexer.whitespace, lexer.whitespace_split, lexer.commenters = ",", True, ""
    try:
        return [part.strip() for part in lexer if part.strip()]
    except ValueError as exc:   # an unbalanced quote
        raise NodeRecordError(f"{exc}: {text!r}") from None


def quoted_pairs(text: str) -> dict[str, str]:
    """`a=1, b="x,y"` -> {'a': '1', 'b': 'x,y'}: keys lower-cased, split at the first `=`, last one wins."""
    pairs: dict[str, str] = {}
    for part in split_quoted(text):
        key, sep, value = part.partition("=")
        if not sep or not key.strip():
            raise NodeRecordError(f"{part!r} is not a key=value pair in {text!r}")
        pairs[key.strip().lower()] = value.strip()
    return pairs


def _number(fields: dict[str, str], key: str, text: str, default: float | None = None) -> float | None:
    raw = fields.get(key)
    if raw is None or raw == "":
        return default
    try:
        return parse_number(raw)
    except FormatError:
        raise NodeRecordError(f"{key.upper()}={raw!r} is not a number in {text!r}") from None


@dataclass(frozen=True)
class NodeRecord:
    """One vehicle's report: position (local x/y), motion, identity, and the text it came in."""

    name: str
    x: float
    y: float
    speed: float = 0.0
    heading: float = 0.0
    depth: float = 0.0
    time: float | None = None
    group: str = ""
    type: str = ""
    length: float = 0.0
    fields: tuple[tuple[str, str], ...] = ()   # every key=value as received (keys lower-cased)
    text: str = ""

    @classmethod
    def parse(cls, text: str, grid=None) -> "NodeRecord":
        """Read a report; one with only LAT/LON is placed with `grid` (the mission's LocalGrid)."""
        try:
            fields = parse_pairs(text)
        except FormatError as exc:
            raise NodeRecordError(f"NODE_REPORT {text!r}: {exc}") from None
        name = fields.get("name", "")
        if not name:
            raise NodeRecordError(f"NODE_REPORT without NAME: {text!r}")
        if "lon" not in fields and "long" in fields:
            fields["lon"] = fields["long"]
        x, y = _number(fields, "x", text), _number(fields, "y", text)
        if x is None or y is None:
            lat, lon = _number(fields, "lat", text), _number(fields, "lon", text)
            if grid is None or lat is None or lon is None:
                raise NodeRecordError(f"NODE_REPORT without X/Y (or LAT/LON and a LatOrigin): {text!r}")
            x, y = grid.to_local(lat, lon)
        depth = _number(fields, "dep", text, None)
        return cls(name=name, x=float(x), y=float(y), speed=_number(fields, "spd", text, 0.0),
                   heading=_number(fields, "hdg", text, 0.0) % 360.0,
                   depth=depth if depth is not None else _number(fields, "depth", text, 0.0),
                   time=_number(fields, "time", text, None) or _number(fields, "utc_time", text, None),
                   group=fields.get("group", ""), type=fields.get("type", ""),
                   length=_number(fields, "length", text, 0.0), fields=tuple(fields.items()), text=text)

    def field(self, key: str, default: str = "") -> str:
        """The value of a report key as it was written (`x`, `spd`, `lat`, ...)."""
        return dict(self.fields).get(key, default)

    def dead_reckoned(self, elapsed: float, decay_start: float, decay_end: float) -> tuple[float, float]:
        """Where the vehicle is `elapsed` s after the report, holding its course: full speed until
        `decay_start`, then a speed falling linearly to zero at `decay_end` (MOOS's `decay = start,end`)."""
        if elapsed <= 0.0 or self.speed == 0.0:
            return self.x, self.y
        travel = min(elapsed, decay_start)
        if elapsed > decay_start and decay_end > decay_start:
            t = min(elapsed, decay_end) - decay_start
            span = decay_end - decay_start
            travel += t - t * t / (2.0 * span)
        dist = self.speed * travel
        rad = math.radians(self.heading)
        return self.x + dist * math.sin(rad), self.y + dist * math.cos(rad)


def velocity(heading: float, speed: float) -> tuple[float, float]:
    """(vx, vy) of a marine heading (degrees, 0 = north, clockwise) and speed."""
    rad = math.radians(heading)
    return speed * math.sin(rad), speed * math.cos(rad)


def cpa_range(osx: float, osy: float, osh: float, osv: float,
              cnx: float, cny: float, cnh: float, cnv: float, horizon: float) -> float:
    """Closest distance between ownship and contact over the next `horizon` s, both holding course and speed."""
    ovx, ovy = velocity(osh, osv)
    cvx, cvy = velocity(cnh, cnv)
    px, py, vx, vy = cnx - osx, cny - osy, cvx - ovx, cvy - ovy
    vv = vx * vx + vy * vy
    t = 0.0 if vv == 0.0 else min(max(-(px * vx + py * vy) / vv, 0.0), horizon)
    return math.hypot(px + vx * t, py + vy * t)


def relative_bearing(osx: float, osy: float, osh: float, cnx: float, cny: float) -> float:
    """Bearing of the contact from ownship's bow, degrees in [0, 360)."""
    absolute = math.degrees(math.atan2(cnx - osx, cny - osy))
    return (absolute - osh) % 360.0


@dataclass(frozen=True)
class NodeMessage:
    """A NODE_MESSAGE: a variable and value one vehicle sends to another (or to a group)."""

    src_node: str
    dest_node: str
    dest_group: str
    var_name: str
    string_val: str | None
    double_val: float | None
    text: str

    @classmethod
    def parse(cls, text: str) -> "NodeMessage":
        """Read and check a message: a source, a destination (node or group), a variable, one value."""
        fields = quoted_pairs(text)
        double_text = fields.get("double_val")
        double_val = None
        if double_text is not None:
            try:
                double_val = parse_number(double_text)
            except FormatError:
                raise NodeRecordError(f"double_val={double_text!r} is not a number in {text!r}") from None
        message = cls(src_node=fields.get("src_node", ""), dest_node=fields.get("dest_node", ""),
                      dest_group=fields.get("dest_group", ""), var_name=fields.get("var_name", ""),
                      string_val=fields.get("string_val"), double_val=double_val, text=text)
        missing = [what for what, ok in (("src_node", message.src_node),
                                         ("dest_node or dest_group", message.dest_node or message.dest_group),
                                         ("var_name", message.var_name)) if not ok]
        if missing:
            raise NodeRecordError(f"NODE_MESSAGE without {', '.join(missing)}: {text!r}")
        if message.string_val and double_val is not None:
            raise NodeRecordError(f"NODE_MESSAGE with both string_val and double_val: {text!r}")
        return message

    @property
    def value(self) -> str | float:
        """What the receiver posts: the string value, else the number (0 when neither is given)."""
        if self.string_val:
            return self.string_val
        return self.double_val if self.double_val is not None else 0.0

    def length(self) -> int:
        """The size uFldNodeComms' max_msg_length limits: the string's characters, at least 2 (a number)."""
        return max(2, len(self.string_val or ""))
