"""pNodeReporter: NODE_REPORT_LOCAL (and PLATFORM_REPORT_LOCAL) in the exact MOOS string format.

`NodeReportBuilder` is pure: it is fed mail and asked for a report at a time;
viewers, the helm's contact ledger and uFldShoreBroker parse what it writes, so
field order and number formatting follow docs/spec/field-apps.md section 3 to the byte.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from moosdb_py.app import MOOSApp
from moosdb_py.config import ConfigLike, ConfigValueError, Param, Params, parse_float, read_params
from moosdb_py.formats import FormatError, format_number, parse_bool, split_quoted
from moosdb_py.geodesy import LocalGrid, mission_grid

CROSSFILL_POLICIES = ("literal", "fill-empty", "use-latest", "global")


def yaw_from_heading(heading: float) -> float:
    """The math-convention angle (90 - heading) in radians, wrapped into [-pi, pi]."""
    rad = math.radians(90.0 - heading)
    return math.atan2(math.sin(rad), math.cos(rad))


@dataclass
class PlatReportInput:
    var: str
    gap: float = 0.0
    alias: str = ""

    @classmethod
    def parse(cls, text: str) -> "PlatReportInput":
        parts = [p.strip() for p in str(text).split(",") if p.strip()]
        if not parts or "=" in parts[0]:
            raise ConfigValueError("plat_report_input", f"expected 'VAR[,gap=secs][,alias=NAME]', got {text!r}")
        item = cls(parts[0])
        for part in parts[1:]:
            key, sep, value = part.partition("=")
            key = key.strip().lower()
            if key == "gap" and sep:
                item.gap = parse_float(value, "plat_report_input gap", lo=0.0)
            elif key == "alias" and sep and value.strip():
                item.alias = value.strip()
            else:
                raise ConfigValueError("plat_report_input", f"unknown field {part!r} in {text!r}")
        return item


@dataclass
class ReporterParams:
    platform_type: str = "unknown"
    platform_color: str = ""
    platform_length: float = 0.0
    platform_beam: float = 0.0
    platform_group: str = ""
    platform_vsource: str = ""
    terse_reports: bool = False
    blackout_interval: float = 0.0
    blackout_variance: float = 0.0
    node_report_output: str = "NODE_REPORT_LOCAL"
    plat_report_output: str = "PLATFORM_REPORT_LOCAL"
    plat_report_inputs: list[PlatReportInput] = field(default_factory=list)
    nohelm_threshold: float = 5.0
    crossfill_policy: str = "literal"
    coord_policy_global: bool = False
    paused: bool = False

    @classmethod
    def from_config(cls, cfg: ConfigLike) -> "ReporterParams":
        v = REPORTER_PARAMS.read(cfg)
        policy = v["crossfill_policy"].lower()
        if policy not in CROSSFILL_POLICIES:
            raise ConfigValueError("crossfill_policy", f"{policy!r} is not one of {', '.join(CROSSFILL_POLICIES)}")
        output = v["node_report_output"]
        if not output.replace("_", "").isalnum():
            raise ConfigValueError("node_report_output", f"{output!r} is not a MOOS variable name")
        same = ("platform_color", "platform_length", "platform_beam", "platform_vsource", "terse_reports",
                "blackout_interval", "blackout_variance", "plat_report_output", "nohelm_threshold",
                "coord_policy_global", "paused")
        return cls(platform_type=v["platform_type"] or v["vessel_type"] or "unknown",
                   platform_group=v["platform_group"] or v["group"], node_report_output=output,
                   plat_report_inputs=[PlatReportInput.parse(t) for t in v["plat_report_input"]],
                   crossfill_policy=policy, **{name: v[name] for name in same})


def summary_modes(summary: str) -> str | None:
    """The `modes=` field of an IVPHELM_SUMMARY, if it has one; fields split as every MOOS string is
    (split_quoted). The summary's other fields are not all key=value, so no parse_pairs. The helm names its
    modes only when they change: a summary without the word is not split at all."""
    if "modes" not in summary.lower():
        return None
    try:
        fields = split_quoted(summary)
    except FormatError:
        return None
    for field in fields:
        key, sep, value = field.partition("=")
        if sep and key.lower() == "modes":
            return value.strip()
    return None


NAV_FIELDS = {"NAV_X": "x", "NAV_Y": "y", "NAV_LAT": "lat", "NAV_LONG": "lon", "NAV_SPEED": "spd",
              "NAV_HEADING": "hdg", "NAV_DEPTH": "dep"}


class NodeReportBuilder:
    """Keeps what pNodeReporter has heard and writes the report strings."""

    def __init__(self, name: str, params: ReporterParams, grid: LocalGrid | None = None,
                 rng: np.random.Generator | None = None):
        self.name = name
        self.params = params
        self.grid = grid
        self.rng = rng or np.random.default_rng()
        self.nav: dict[str, float] = {}
        self.xy_time = -math.inf
        self.latlon_time = -math.inf
        self.yaw_seen = False
        self.helm_state: str | None = None
        self.helm_state_time = 0.0
        self.helm_modes: str | None = None
        self.allstop = "unknown"
        self.mode_aux = ""
        self.load_warning = ""
        self.thrust_mode_reverse = False
        self.transparency: float | None = None
        self.color = params.platform_color
        self.group = params.platform_group
        self.paused = params.paused
        self.index = 0
        self._next_post_time = -math.inf
        self.plat_values: dict[str, str] = {}
        self._plat_changed: set[str] = set()
        self._plat_last_post: dict[str, float] = {}
        self._plat_vars = frozenset(item.var for item in params.plat_report_inputs)   # checked on every mail

    # ---- input ---------------------------------------------------------------------------
    def on_mail(self, key: str, value, time: float) -> None:
        """Take one message; values of the wrong type for a known key are ignored."""
        if isinstance(value, (int, float)):
            self._on_double(key, float(value), time)
        elif isinstance(value, str):
            self._on_string(key, value, time)
        if key in self._plat_vars:
            text = format_number(value, 6) if isinstance(value, (int, float)) else str(value)
            if self.plat_values.get(key) != text:
                self.plat_values[key] = text
                self._plat_changed.add(key)

    def _on_double(self, key: str, value: float, time: float) -> None:
        field = NAV_FIELDS.get(key)
        if field is not None:
            self.nav[field] = value
            if key in ("NAV_X", "NAV_Y"):
                self.xy_time = time
            elif key in ("NAV_LAT", "NAV_LONG"):
                self.latlon_time = time
        elif key == "NAV_YAW":
            self.yaw_seen = True
        elif key == "NAV_TRANSP":
            self.transparency = value

    def _on_string(self, key: str, value: str, time: float) -> None:
        word = value.strip()
        if key == "IVPHELM_STATE":
            self.helm_state = word
            self.helm_state_time = time
        elif key == "IVPHELM_SUMMARY":
            modes = summary_modes(word)
            if modes is not None:
                self.helm_modes = modes
        elif key == "IVPHELM_ALLSTOP":
            self.allstop = word
        elif key == "AUX_MODE":
            self.mode_aux = word
        elif key == "LOAD_WARNING":
            self.load_warning = word
        elif key == "THRUST_MODE_REVERSE":
            self.thrust_mode_reverse = self._flag(word, self.thrust_mode_reverse)
        elif key == "NODE_GROUP_UPDATE":
            self.group = word
        elif key in ("NODE_COLOR_CHANGE", "PLATFORM_COLOR"):
            self.color = word
        elif key == "PNR_PAUSE":
            self.paused = self._flag(word, self.paused)

    @staticmethod
    def _flag(word: str, current: bool) -> bool:
        """A MOOS boolean in mail; anything else leaves the setting as it was."""
        try:
            return parse_bool(word)
        except FormatError:
            return current

    # ---- output --------------------------------------------------------------------------
    def mode(self, now: float) -> str:
        if self.helm_state is None:
            return "NOHELM-EVER"
        age = now - self.helm_state_time
        if age > self.params.nohelm_threshold:
            return f"NOHELM-{int(age)}"
        if self.helm_state == "DRIVE" and self.helm_modes:
            return self.helm_modes
        return self.helm_state

    def position(self) -> dict[str, float]:
        """x, y, lat, lon as known, cross-filled per the crossfill policy."""
        pos = {k: self.nav[k] for k in ("x", "y", "lat", "lon") if k in self.nav}
        has_xy = "x" in pos and "y" in pos
        has_ll = "lat" in pos and "lon" in pos
        policy = self.params.crossfill_policy
        if self.grid is None or policy == "literal":
            return pos
        from_ll = has_ll and (
            policy == "global"
            or (policy == "fill-empty" and not has_xy)
            or (policy == "use-latest" and self.latlon_time > self.xy_time))
        from_xy = has_xy and not from_ll and (
            (policy == "fill-empty" and not has_ll)
            or (policy == "use-latest" and self.xy_time >= self.latlon_time))
        if from_ll:
            pos["x"], pos["y"] = self.grid.to_local(pos["lat"], pos["lon"])
        elif from_xy:
            pos["lat"], pos["lon"] = self.grid.to_latlon(pos["x"], pos["y"])
        return pos

    def node_report(self, now: float) -> str | None:
        """The next NODE_REPORT_LOCAL value, or None (no nav yet, paused, or in blackout)."""
        pos = self.position()
        if self.paused or not (("x" in pos and "y" in pos) or ("lat" in pos and "lon" in pos)):
            return None
        if now < self._next_post_time:
            return None
        p = self.params
        fields: list[tuple[str, str]] = [("NAME", self.name)]
        if not p.coord_policy_global and "x" in pos and "y" in pos:
            fields += [("X", format_number(pos["x"], 2)), ("Y", format_number(pos["y"], 2))]
        hdg = self.nav.get("hdg", 0.0)
        fields += [("SPD", format_number(self.nav.get("spd", 0.0), 2)), ("HDG", format_number(hdg, 2))]
        if not p.terse_reports:
            fields.append(("DEP", format_number(self.nav.get("dep", 0.0), 2)))
        if "lat" in pos and "lon" in pos and (not p.terse_reports or p.coord_policy_global):
            fields += [("LAT", format_number(pos["lat"], 8)), ("LON", format_number(pos["lon"], 8))]
        fields.append(("TYPE", p.platform_type))
        optional = [("COLOR", self.color), ("GROUP", self.group), ("VSOURCE", p.platform_vsource)]
        fields += [(k, v) for k, v in optional if v]
        fields.append(("MODE", self.mode(now)))
        if self.mode_aux:
            fields.append(("MODE_AUX", self.mode_aux))
        fields.append(("ALLSTOP", self.allstop))
        if self.load_warning:
            fields.append(("LOAD_WARNING", self.load_warning))
        if self.index:
            fields.append(("INDEX", str(self.index)))
        if self.thrust_mode_reverse:
            fields.append(("THRUST_MODE_REVERSE", "true"))
        if self.yaw_seen and not p.terse_reports:
            fields.append(("YAW", format_number(yaw_from_heading(hdg), 7)))
        fields.append(("TIME", format_number(now, 2)))
        if self.transparency is not None:
            fields.append(("TRANSPARENCY", format_number(self.transparency, 2)))
        if p.platform_length:
            fields.append(("LENGTH", format_number(p.platform_length, 2)))
        if p.platform_beam:
            fields.append(("BEAM", format_number(p.platform_beam, 2)))
        self.index += 1
        if p.blackout_interval > 0.0:
            jitter = self.rng.uniform(-p.blackout_variance, p.blackout_variance) if p.blackout_variance else 0.0
            self._next_post_time = now + max(0.0, p.blackout_interval + jitter)
        return ",".join(f"{k}={v}" for k, v in fields)

    def platform_report(self, now: float) -> str | None:
        """PLATFORM_REPORT_LOCAL when a configured input changed and its gap has passed."""
        due = [item for item in self.params.plat_report_inputs
               if item.var in self._plat_changed
               and now - self._plat_last_post.get(item.var, -math.inf) >= item.gap]
        if not due:
            return None
        for item in due:
            self._plat_changed.discard(item.var)
            self._plat_last_post[item.var] = now
        parts = [f"platform={self.name}", f"utc_time={format_number(now, 2)}"]
        parts += [f"{item.alias or item.var}={self.plat_values[item.var]}"
                  for item in self.params.plat_report_inputs if item.var in self.plat_values]
        return ",".join(parts)


REPORTER_PARAMS = Params(
    Param("platform_type", str, "", "kayak, uuv, ship, ... (default unknown)"),
    Param("vessel_type", str, "", "older name of platform_type"),
    Param("platform_color", str, "", "e.g. yellow"),
    Param("platform_length", float, 0.0, "metres (LENGTH= when > 0)", lo=0.0),
    Param("platform_beam", float, 0.0, "metres (BEAM= when > 0)", lo=0.0),
    Param("platform_group", str, "", "GROUP="),
    Param("group", str, "", "older name of platform_group"),
    Param("platform_vsource", str, "", "VSOURCE="),
    Param("terse_reports", bool, False, "leave out DEP, YAW, LAT, LON"),
    Param("coord_policy_global", bool, False, "report LAT/LON only, no X/Y"),
    Param("crossfill_policy", str, "literal", "literal, fill-empty, use-latest or global (x/y <-> lat/lon)"),
    Param("nohelm_threshold", float, 5.0, "s without IVPHELM_STATE before MODE=NOHELM-<secs>", lo=0.0),
    Param("blackout_interval", float, 0.0, "s between reports (0 = every iteration)", lo=0.0),
    Param("blackout_variance", float, 0.0, "s of uniform jitter on the blackout interval", lo=0.0),
    Param("node_report_output", str, "NODE_REPORT_LOCAL", "the variable the report goes to"),
    Param("plat_report_input", list, [], "`VAR[,gap=secs][,alias=NAME]`, one per line"),
    Param("plat_report_output", str, "PLATFORM_REPORT_LOCAL", "the variable the platform report goes to"),
    Param("paused", bool, False, "start without reporting (PNR_PAUSE=false resumes)"),
)
REPORTER_INPUTS = ("NAV_X", "NAV_Y", "NAV_LAT", "NAV_LONG", "NAV_SPEED", "NAV_HEADING", "NAV_DEPTH", "NAV_YAW",
                   "NAV_TRANSP", "IVPHELM_SUMMARY", "IVPHELM_STATE", "IVPHELM_ALLSTOP", "AUX_MODE",
                   "LOAD_WARNING", "THRUST_MODE_REVERSE", "NODE_GROUP_UPDATE", "NODE_COLOR_CHANGE",
                   "PNR_PAUSE", "PLATFORM_COLOR")


class NodeReporter(MOOSApp):
    """pNodeReporter: posts this vehicle's NODE_REPORT_LOCAL every iteration.

    The report is the comma list MOOS viewers, the helm's contact ledger and the shore
    broker read: NAME (the Community), X, Y, SPD, HDG, DEP, LAT, LON, TYPE, COLOR, GROUP,
    MODE (the helm's state or mode, NOHELM-EVER / NOHELM-<secs> without a helm), ALLSTOP,
    INDEX, YAW, TIME, LENGTH, ... Numbers have at most 2 decimals (8 for LAT/LON). The first
    report also goes to NODE_REPORT_LOCAL_FIRST. Variables named by plat_report_input are
    bundled into PLATFORM_REPORT_LOCAL when they change.
    """

    default_name = "pNodeReporter"
    parameters = REPORTER_PARAMS
    example_config = """\
ProcessConfig = pNodeReporter
{
  AppTick   = 2
  CommsTick = 2

  platform_type    = unknown   // alias vessel_type: kayak, uuv, ship, ...
  platform_color   =           // e.g. yellow
  platform_length  = 0         // metres (LENGTH= when > 0)
  platform_beam    = 0         // metres (BEAM= when > 0)
  platform_group   =           // alias group
  platform_vsource =           // VSOURCE=
  terse_reports    = false     // leave out DEP, YAW, LAT, LON
  coord_policy_global = false  // report LAT/LON only, no X/Y
  crossfill_policy = literal   // literal | fill-empty | use-latest | global (x/y <-> lat/lon)
  nohelm_threshold = 5         // s without IVPHELM_STATE before MODE=NOHELM-<secs>
  blackout_interval = 0        // s between reports (0 = every iteration)
  blackout_variance = 0        // s of uniform jitter on the blackout interval
  node_report_output = NODE_REPORT_LOCAL
  plat_report_input  =         // VAR[,gap=secs][,alias=NAME], repeatable
  plat_report_output = PLATFORM_REPORT_LOCAL
  paused = false               // start without reporting (PNR_PAUSE=false resumes)
}
"""
    interface = """\
SUBSCRIPTIONS:
  NAV_X, NAV_Y, NAV_LAT, NAV_LONG, NAV_SPEED, NAV_HEADING, NAV_DEPTH, NAV_YAW, NAV_TRANSP
  IVPHELM_STATE, IVPHELM_SUMMARY, IVPHELM_ALLSTOP, AUX_MODE, LOAD_WARNING, THRUST_MODE_REVERSE
  NODE_GROUP_UPDATE, NODE_COLOR_CHANGE, PLATFORM_COLOR, PNR_PAUSE = true|false
  every plat_report_input variable
PUBLICATIONS:
  NODE_REPORT_LOCAL (or node_report_output), NODE_REPORT_LOCAL_FIRST (once)
  PLATFORM_REPORT_LOCAL (or plat_report_output)
  PNODEREPORTER_PID (the process id, once at start-up: what uMemWatch measures)
"""

    def on_startup(self) -> None:
        params = read_params(self.config, ReporterParams.from_config)
        name = (self.mission.community if self.mission is not None else "") or "unknown"
        self.builder = NodeReportBuilder(name, params, mission_grid(self.mission))
        self.notify("PNODEREPORTER_PID", float(os.getpid()))   # as MOOS-IvP's, for uMemWatch (sent on connecting)

    def on_connect(self) -> None:
        for key in REPORTER_INPUTS:
            self.register(key)
        for item in self.builder.params.plat_report_inputs:
            self.register(item.var)

    def on_new_mail(self, mail) -> None:
        for msg in mail:
            self.builder.on_mail(msg.key, msg.value, msg.time)

    def iterate(self) -> None:
        now = self.moos_time()
        params = self.builder.params
        first = self.builder.index == 0
        report = self.builder.node_report(now)
        if report is not None:
            self.notify(params.node_report_output, report, now)
            if first:
                self.notify(f"{params.node_report_output}_FIRST", report, now)
        platform = self.builder.platform_report(now)
        if platform is not None:
            self.notify(params.plat_report_output, platform, now)

    def status_fields(self) -> dict:
        return {"reports": self.builder.index, "mode": self.builder.mode(self.moos_time())}


main = NodeReporter.main
