"""pContactMgrV20 (and pBasicContactMgr): the vehicle's contact list, its reports, and the alerts
that make the helm spawn a behaviour (BHV_AvoidCollision) per contact.

`ContactManager` is pure: it takes mail (`on_mail`) and the clock (`iterate`) and returns the
postings. Alert semantics follow the MOOS-IvP documentation of pContactMgrV20: an alert `id` has
on/off flags (`var`/`val` make one on-flag), an `alert_range` and a `cpa_range` (never below the
alert range); it applies to a contact whose report is at most `contact_max_age` old, that passes
the filters, and whose range is within `cpa_range` and either the range or the CPA range is within
`alert_range`. On-flags post once when an alert starts to apply, off-flags once when it stops; a
contact retired for age forgets its alerts, so it is alerted afresh if it comes back.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import shapely

from behaviors.flags import FlagError, FlagSpec, expand_macros, parse_flag
from behaviors.geometry import GeometryError, parse_polygon
from moosdb_py.formats import FormatError, format_number, is_number, parse_bool, parse_pairs, split_quoted
from moosdb_py.config import ConfigValueError, Param, Params, read_params
from moosdb_py.geodesy import mission_grid
from oilspill_moos.machine_app import MachineApp
from behaviors.contacts import NodeRecord, NodeRecordError, cpa_range, relative_bearing

log = logging.getLogger(__name__)

Post = tuple[str, str | float]
CPA_HORIZON = 36000.0   # s: the contact manager's CPA looks ten hours ahead
RANGE_UNSET, RANGE_OFF = -1.0, -2.0
FILTER_KEYS = ("match_name", "ignore_name", "match_group", "ignore_group", "match_type", "ignore_type",
               "match_region", "ignore_region")


class AlertError(ValueError):
    """An alert configuration (mission line or BCM_ALERT_REQUEST) that cannot be used; `text` is the line."""

    def __init__(self, message: str, text: str = ""):
        super().__init__(message)
        self.text = text


@dataclass
class ContactFilter:
    """Which contacts count: names, groups and types matched or ignored (comma lists, any case),
    and polygons the contact must be in (match_region) or not be in (ignore_region)."""

    lists: dict[str, set[str]] = field(default_factory=dict)
    regions: dict[str, list[shapely.Polygon]] = field(default_factory=dict)
    strict_ignore: bool = True

    def add(self, key: str, value: str) -> None:
        if key == "strict_ignore":
            try:
                self.strict_ignore = parse_bool(value)
            except FormatError as exc:
                raise AlertError(f"strict_ignore: {exc}") from None
        elif key.endswith("_region"):
            try:
                self.regions.setdefault(key, []).append(shapely.Polygon(parse_polygon(value)))
            except GeometryError as exc:
                raise AlertError(f"{key}: {exc}") from None
        else:
            self.lists.setdefault(key, set()).update(v.strip().lower() for v in value.split(",") if v.strip())

    def accepts(self, record: NodeRecord) -> bool:
        for what, value in (("name", record.name), ("group", record.group), ("type", record.type)):
            value = value.lower()
            ignored = self.lists.get(f"ignore_{what}", set())
            if value in ignored or (not value and ignored and self.strict_ignore and what != "name"):
                return False
            matched = self.lists.get(f"match_{what}")
            if matched and value not in matched:
                return False
        point = shapely.Point(record.x, record.y)
        if any(poly.covers(point) for poly in self.regions.get("ignore_region", [])):
            return False
        inside = self.regions.get("match_region")
        return not inside or any(poly.covers(point) for poly in inside)


@dataclass
class Alert:
    """One alert id: its flags, ranges and filter; `source` says who asked for it."""

    id: str
    range: float = RANGE_UNSET
    cpa_range: float = RANGE_UNSET
    range_given: bool = False    # said by the alert itself (pBasicContactMgr's defaults fill the rest)
    cpa_given: bool = False
    var: str = ""
    val: str = ""
    on_flags: list[FlagSpec] = field(default_factory=list)
    off_flags: list[FlagSpec] = field(default_factory=list)
    filter: ContactFilter = field(default_factory=ContactFilter)
    source: str = ""

    def ranges(self, defaults: tuple[float, float] | None = None) -> tuple[float, float]:
        """(alert range, cpa range) in force: the alert's own, else the block's defaults (pBasicContactMgr)."""
        if defaults is None:
            return self.range, self.cpa_range
        rng = self.range if self.range_given else defaults[0]
        return rng, self.cpa_range if self.cpa_given else max(defaults[1], rng)

    def valid(self, defaults: tuple[float, float] | None = None) -> bool:
        return self.ranges(defaults)[0] != RANGE_UNSET and bool(self.on_flags or self.off_flags)

    def set_range(self, text: str, far: bool) -> None:
        if far:
            self.cpa_given = True
        else:
            self.range_given = True
        if text.strip().lower() == "off":
            self.cpa_range = RANGE_OFF
            if not far:
                self.range = RANGE_OFF
            return
        value = float(text) if is_number(text) else None
        if value is None or value < 0:
            raise AlertError(f"{'cpa_range' if far else 'alert_range'}={text!r} is not a range >= 0")
        if far:
            self.cpa_range = value
            self.range = min(self.range, value)
        else:
            self.range = value
            self.cpa_range = max(self.cpa_range, value)

    def configure(self, fields: list[str]) -> None:
        """Apply `key=value` parts of one alert line (the `id=` part already taken). `var` and `val`
        make one on-flag, even from separate lines (as older missions write them)."""
        for part in fields:
            key, sep, value = part.partition("=")
            key, value = key.strip().lower(), value.strip()
            if not sep:
                raise AlertError(f"{part!r} is not a key=value pair")
            if key == "id":
                continue
            if key == "var":
                self.var = value
            elif key in ("val", "pattern"):
                self.val = value
            elif key in ("on_flag", "onflag"):
                self._add_flag(self.on_flags, value)
            elif key in ("off_flag", "offflag"):
                for one in value.split("#"):   # several off flags may share one line
                    self._add_flag(self.off_flags, one)
            elif key in ("alert_range", "cpa_range", "range", "range_cpa"):   # range, range_cpa: pBasicContactMgr
                self.set_range(value, far=key in ("cpa_range", "range_cpa"))
            elif key in ("range_color", "range_cpa_color", "range_cpa_time"):
                continue   # drawing, and a CPA time the C++ apps no longer use
            elif key in FILTER_KEYS or key == "strict_ignore":
                self.filter.add(key, value)
            else:
                raise AlertError(f"unknown alert component {key!r}")
        if self.var and self.val:
            self._add_flag(self.on_flags, f"{self.var}={self.val}")

    @staticmethod
    def _add_flag(flags: list[FlagSpec], text: str) -> None:
        try:
            flag = parse_flag(text)
        except FlagError as exc:
            raise AlertError(str(exc)) from None
        if flag is not None and flag not in flags:
            flags.append(flag)

    def applies(self, range_actual: float, range_cpa: float, defaults: tuple[float, float] | None = None) -> bool:
        """The range test (a range switched off, or not positive, leaves only the filters)."""
        alert_range, cpa_range = self.ranges(defaults)
        if alert_range <= 0:
            return True
        if range_actual > cpa_range:
            return False
        return range_actual <= alert_range or range_cpa <= alert_range


@dataclass
class ContactMgrParams:
    """The pContactMgrV20 block, with the documented defaults."""

    alerts: list[str] = field(default_factory=list)
    filter_lines: list[tuple[str, str]] = field(default_factory=list)
    contact_max_age: float = 60.0
    max_retired_history: int = 5
    decay: tuple[float, float] = (15.0, 30.0)
    recap_interval: float = 1.0   # <= 0: off
    range_report_timeout: float = 10.0
    range_report_maxsize: int = 20
    post_closest_range: bool = False
    post_closest_relbng: bool = False
    post_all_ranges: bool = False
    reject_range: float = 2000.0   # <= 0: off
    max_contacts: int = 500
    alert_verbose: bool = False
    hold_alerts_for_helm: bool = False
    contact_local_coords: str = "verbatim"
    default_ranges: tuple[float, float] | None = None   # pBasicContactMgr: ranges of alerts that give none

    @classmethod
    def from_config(cls, cfg, basic: bool = False) -> "ContactMgrParams":
        """The block; `basic` reads it as pBasicContactMgr does (default alert ranges, contacts kept an hour)."""
        v = CONTACT_MGR_PARAMS.read(cfg)
        decay_text = v["decay"]
        start, _, end = decay_text.partition(",")
        start_v, end_v = (float(t) if is_number(t) else None for t in (start, end))
        if start_v is None or end_v is None or not 0 <= start_v <= end_v:
            raise ConfigValueError("decay", f"expected 'start,end' seconds with 0 <= start <= end, got {decay_text!r}")
        coords = v["contact_local_coords"].lower()
        if coords not in ("verbatim", "lazy_lat_lon", "force_lat_lon"):
            raise ConfigValueError("contact_local_coords", f"{coords!r} is not verbatim, lazy_lat_lon or force_lat_lon")
        same = ("max_retired_history", "range_report_timeout", "range_report_maxsize", "post_closest_range",
                "post_closest_relbng", "post_all_ranges", "max_contacts", "alert_verbose", "hold_alerts_for_helm")
        max_age = v["contact_max_age"]
        return cls(
            alerts=v["alert"],
            filter_lines=[(key, line) for key in (*FILTER_KEYS, "strict_ignore") for line in v[key]],
            contact_max_age=(3600.0 if basic else 60.0) if max_age is None else max_age,
            decay=(start_v, end_v),
            recap_interval=_off_or_float(v, "recap_interval" if v["recap_interval"] else "contacts_recap_interval", 1.0),
            reject_range=_off_or_float(v, "reject_range", 2000.0),
            contact_local_coords=coords,
            default_ranges=(_first_float(v, BASIC_RANGE_KEYS, 1000.0), _first_float(v, BASIC_CPA_KEYS, 1000.0))
            if basic else None,
            **{name: v[name] for name in same},
        )


BASIC_RANGE_KEYS = ("default_alert_range", "alert_range")
BASIC_CPA_KEYS = ("default_cpa_range", "default_alert_range_cpa", "alert_cpa_range")


def _first_float(values: dict, keys: tuple[str, ...], default: float) -> float:
    """The first of several spellings the block gives (all positive numbers), else `default`."""
    return next((values[k] for k in keys if values[k] is not None), default)


def _off_or_float(values: dict, key: str, default: float) -> float:
    """`off` -> -1; a number >= 0; blank -> `default`."""
    text = values[key]
    if text.lower() == "off":
        return -1.0
    return Param(key, float, default, "", lo=0.0).read(values)


def alert_macros(record: NodeRecord) -> dict[str, str]:
    """The `$[..]` macros an alert flag may name, from the contact's report as written."""
    return {"X": record.field("x"), "Y": record.field("y"), "LAT": record.field("lat"),
            "LON": record.field("lon"), "SPD": record.field("spd"), "HDG": record.field("hdg"),
            "DEP": record.field("dep"), "VNAME": record.name, "VTYPE": record.type, "GROUP": record.group,
            "UTIME": record.field("time")}


def expand_alert(value: str | float, record: NodeRecord) -> str | float:
    if not isinstance(value, str):
        return value
    for name in ("VNAME", "VTYPE", "GROUP"):   # %[..]: the same, lower-cased
        value = value.replace(f"%[{name}]", alert_macros(record)[name].lower())
    return expand_macros(value, alert_macros(record))


@dataclass
class RangeReport:
    """A BCM_REPORT_REQUEST: post to `var` the contacts within `range` (of a group/type, if given)."""

    range: float
    group: str = ""
    type: str = ""
    refresh: bool = False
    requested: float = 0.0
    last: str | None = None


class ContactManager:
    """The contact ledger and alert logic of pContactMgrV20, free of I/O."""

    def __init__(self, ownship: str, params: ContactMgrParams, grid=None):
        self.ownship = ownship
        self.params = params
        self.grid = grid if params.contact_local_coords != "verbatim" else None
        self.filter = ContactFilter()
        self.filter.lists["ignore_name"] = {ownship.lower()}
        for key, value in params.filter_lines:
            self.filter.add(key, value)
        self.alerts: dict[str, Alert] = {}
        for line in reversed(params.alerts):   # the C++ app reads its block bottom-up
            self.configure_alert(line, "")
        self.nav = {"x": 0.0, "y": 0.0, "heading": 0.0, "speed": 0.0}
        self.contacts: dict[str, NodeRecord] = {}
        self.heard: dict[str, float] = {}                # contact -> MOOS time its last report arrived
        self.ranges: dict[str, tuple[float, float, float]] = {}   # contact -> actual, extrapolated, CPA
        self.alerted: set[tuple[str, str]] = set()       # (contact, alert id)
        self.filtered: set[str] = set()
        self.retired: list[str] = []
        self.reports: dict[str, RangeReport] = {}
        self.helm_driving = False
        self.warnings: list[str] = []
        # what was posted last, starting from the values the C++ app starts from
        self._last: dict[str, str | float] = {"CONTACTS_RETIRED": "", "CONTACTS_LIST": "", "CONTACTS_ALERTED": "",
                                              "CONTACTS_COUNT": 0.0, "CONTACT_CLOSEST_RANGE": 0.0}
        self._recap_time = -math.inf

    # ---- input ---------------------------------------------------------------------------
    def configure_alert(self, text: str, source: str) -> Alert:
        """An `alert =` line or a BCM_ALERT_REQUEST: create or extend the alert named by `id`."""
        try:
            parts = split_quoted(text)
            ids = [p.partition("=")[2].strip() for p in parts if p.partition("=")[0].strip().lower() == "id"]
            alert_id = (ids[-1] if ids else "") or "no_id"
            alert = self.alerts.setdefault(alert_id, Alert(alert_id))
            if source:
                alert.source = source
            alert.configure(parts)
        except (NodeRecordError, AlertError, FormatError) as exc:
            raise AlertError(f"alert {text!r}: {exc}", text) from None
        return alert

    def on_mail(self, key: str, value, now: float, source: str = "") -> None:
        """One piece of mail; a bad NODE_REPORT or alert request becomes a warning."""
        try:
            if key in ("NAV_X", "NAV_Y", "NAV_HEADING", "NAV_SPEED") and isinstance(value, (int, float)):
                self.nav[key[4:].lower()] = float(value)
            elif key == "NODE_REPORT" and isinstance(value, str):
                self.on_node_report(value, now)
            elif key == "BCM_ALERT_REQUEST" and isinstance(value, str):
                self.configure_alert(value, source or "mail")
            elif key == "BCM_REPORT_REQUEST" and isinstance(value, str):
                self.on_report_request(value, now)
            elif key == "IVPHELM_STATE" and isinstance(value, str) and value.strip() == "DRIVE":
                self.helm_driving = True
        except (NodeRecordError, AlertError, ValueError) as exc:
            self.warnings.append(f"{key} from {source or '?'} ignored: {exc}")

    def on_node_report(self, text: str, now: float) -> None:
        record = NodeRecord.parse(text, self.grid)
        if self.params.contact_local_coords == "force_lat_lon" and self.grid is not None and record.field("lat"):
            x, y = self.grid.to_local(float(record.field("lat")), float(record.field("lon")))
            record = replace(record, x=float(x), y=float(y))
        if record.name.lower() == self.ownship.lower():
            return
        if not self.filter.accepts(record):
            self.filtered.add(record.name)
            return
        self.contacts[record.name] = record
        self.heard[record.name] = now
        if record.name in self.retired:
            self.retired.remove(record.name)

    def on_report_request(self, text: str, now: float) -> None:
        fields = parse_pairs(text, unquoted=True)
        var, rng = fields.get("var", ""), fields.get("range", "")
        rng = float(rng) if is_number(rng) else None
        unknown = set(fields) - {"var", "range", "group", "type", "refresh", "reason"}
        if not var or " " in var or rng is None or rng < 0 or unknown:
            raise AlertError(f"BCM_REPORT_REQUEST needs var=<VAR>,range=<metres>[,group,type,refresh]: {text!r}")
        report = self.reports.get(var)
        if report is None or report.range != rng:
            report = self.reports[var] = RangeReport(rng, fields.get("group", ""), fields.get("type", ""))
        report.requested, report.refresh = now, fields.get("refresh", "").lower() == "true"

    # ---- work ----------------------------------------------------------------------------
    def contact_time(self, name: str) -> float:
        """The report's own TIME, else when it arrived."""
        record = self.contacts[name]
        return record.time if record.time is not None else self.heard[name]

    def update_ranges(self, now: float) -> None:
        osx, osy, osh, osv = self.nav["x"], self.nav["y"], self.nav["heading"], self.nav["speed"]
        for name, record in self.contacts.items():
            actual = math.hypot(osx - record.x, osy - record.y)
            cnx, cny = record.dead_reckoned(now - self.contact_time(name), *self.params.decay)
            extrap = math.hypot(osx - cnx, osy - cny)
            cpa = cpa_range(osx, osy, osh, osv, cnx, cny, record.heading, record.speed, CPA_HORIZON)
            self.ranges[name] = (actual, extrap, cpa)

    def alert_applies(self, name: str, alert: Alert, now: float) -> bool:
        if not alert.valid(self.params.default_ranges) or now - self.contact_time(name) > self.params.contact_max_age:
            return False
        if not alert.filter.accepts(self.contacts[name]):
            return False
        actual, _, cpa = self.ranges[name]
        return alert.applies(actual, cpa, self.params.default_ranges)

    def check_alerts(self, now: float) -> list[Post]:
        posts: list[Post] = []
        for name in sorted(self.contacts):
            for alert_id, alert in sorted(self.alerts.items()):
                was = (name, alert_id) in self.alerted
                now_applies = self.alert_applies(name, alert, now)
                if now_applies == was:
                    continue
                flags = alert.on_flags if now_applies else alert.off_flags
                posts += [(flag.var, expand_alert(flag.value, self.contacts[name])) for flag in flags]
                (self.alerted.add if now_applies else self.alerted.discard)((name, alert_id))
                if self.params.alert_verbose:
                    actual, _, cpa = self.ranges[name]
                    alert_range, cpa_range = alert.ranges(self.params.default_ranges)
                    text = (f"contact={name},alert_id={alert_id},{'off-->alerted' if now_applies else 'alerted-->off'},"
                            f"alert_range={format_number(alert_range, 1)},alert_range_cpa={format_number(cpa_range, 1)},"
                            f"range_actual={actual:.1f}" + (f",range_cpa={cpa:.1f}" if now_applies else ""))
                    posts.append(("ALERT_VERBOSE", text))
        return posts

    def retire(self, now: float) -> None:
        """Drop contacts that are too old, too far (5 % hysteresis) or filtered out; keep at most
        max_contacts (the stalest first, then the farthest)."""
        gone = set(self.filtered) & set(self.contacts)
        for name in self.contacts:
            if now - self.contact_time(name) > self.params.contact_max_age:
                gone.add(name)
            elif self.params.reject_range > 0 and self.ranges[name][0] > 1.05 * self.params.reject_range:
                gone.add(name)
        excess = len(self.contacts) - len(gone) - self.params.max_contacts
        if excess > 0:
            gone |= {n for n in self.contacts if now - self.contact_time(n) > self.params.contact_max_age / 2}
            excess = len(self.contacts) - len(gone) - self.params.max_contacts
            by_range = sorted((n for n in self.contacts if n not in gone), key=lambda n: self.ranges[n][0])
            gone |= set(by_range[len(by_range) - excess:]) if excess > 0 else set()
        for name in sorted(gone):
            self.retired.insert(0, name)
            for table in (self.contacts, self.heard, self.ranges):
                table.pop(name, None)
            self.alerted = {pair for pair in self.alerted if pair[0] != name}
        self.filtered.clear()

    def range_reports(self, now: float) -> list[Post]:
        stale = [v for v, r in self.reports.items() if now - r.requested >= self.params.range_report_timeout]
        if len(self.reports) > self.params.range_report_maxsize and stale:
            del self.reports[max(stale, key=lambda v: now - self.reports[v].requested)]
        posts: list[Post] = []
        for var, report in self.reports.items():
            names = [n for n in sorted(self.contacts) if self.ranges[n][1] < report.range
                     and (not report.group or report.group.lower() == self.contacts[n].group.lower())
                     and (not report.type or report.type.lower() == self.contacts[n].type.lower())]
            text = ",".join(names)
            if report.refresh or text != report.last:
                posts.append((var, text))
                report.last, report.refresh = text, False
        return posts

    def summaries(self, now: float) -> list[Post]:
        """CONTACTS_* and CONTACT_CLOSEST*: each posted when it changes (the recap on its interval)."""
        posts: list[Post] = []
        retired = ",".join(self.retired)
        del self.retired[self.params.max_retired_history:]
        names = sorted(self.contacts)
        closest = min(names, key=lambda n: self.ranges[n][0], default="")
        alerted = sorted(self.alerted)
        changed = {"CONTACTS_RETIRED": retired, "CONTACTS_LIST": ",".join(names),
                   "CONTACTS_ALERTED": "".join(f"({n},{a})" for n, a in alerted),
                   "CONTACTS_COUNT": float(len(alerted))}
        if closest:
            record = self.contacts[closest]
            changed["CONTACT_CLOSEST"] = closest
            if self.params.post_closest_range:
                changed["CONTACT_CLOSEST_RANGE"] = float(int(self.ranges[closest][0]))
            if self.params.post_closest_relbng:
                changed["CONTACT_CLOSEST_RELBNG"] = float(int(relative_bearing(
                    self.nav["x"], self.nav["y"], self.nav["heading"], record.x, record.y)))
        for key, value in changed.items():
            if self._last.get(key) != value:
                posts.append((key, value))
                self._last[key] = value
                if key == "CONTACT_CLOSEST":
                    posts.append(("CONTACT_CLOSEST_TIME", now))
        if self.params.recap_interval > 0 and now - self._recap_time > self.params.recap_interval:
            self._recap_time = now
            posts.append(("CONTACTS_RECAP", " # ".join(
                f"vname={n},range={self.ranges[n][0]:.2f},age={now - self.contact_time(n):.2f}" for n in names)))
        if self.params.post_all_ranges:
            posts.append(("CONTACT_RANGES", ",".join(format_number(r, 1) for r in sorted(
                self.ranges[n][0] for n in names))))
        return posts

    def iterate(self, now: float) -> list[Post]:
        self.update_ranges(now)
        posts: list[Post] = []
        if not self.params.hold_alerts_for_helm or self.helm_driving:
            posts += self.check_alerts(now)
        self.retire(now)
        return posts + self.range_reports(now) + self.summaries(now)


# Accepted for C++ missions, but only drawn or logged there: one summary line, not a warning each.
NOT_IMPLEMENTED_KEYS = frozenset({
    "display_radii", "display_radii_id", "alert_range_color", "cpa_range_color", "default_alert_range_color",
    "default_cpa_range_color", "app_logging", "disable_var", "enable_var", "able_flag", "disable_flag",
    "enable_flag", "early_warning_time", "early_warning_rng", "early_warning_radii", "ewarn_radii_color",
    "early_warning_ref_spd", "early_warning_flag", "cease_warning_flag", "retire_flag", "alert_range",
    "alert_cpa_range", "alert_cpa_time", "default_alert_range_cpa_time"})
CONTACT_MGR_PARAMS = Params(
    Param("alert", list, [], "`id=.., var=.., val=.., alert_range=.., cpa_range=.., on_flag=.., off_flag=..` "
                             "(repeatable; lines of one id add up)"),
    *(Param(key, list, [], f"contact filter: {key.replace('_', ' ')} (comma lists, repeatable)") for key in FILTER_KEYS),
    Param("strict_ignore", list, [], "true: an ignore list also drops contacts that do not say"),
    Param("contact_max_age", float, None, "s since the last report before a contact is retired (default 60; "
                                          "3600 for pBasicContactMgr)", lo=0.0),
    Param("max_retired_history", int, 5, "names kept in CONTACTS_RETIRED", 1, 50),
    Param("reject_range", str, "", "m; contacts farther are retired (off: never; default 2000)"),
    Param("max_contacts", int, 500, "contacts kept at most", lo=1),
    Param("decay", str, "15,30", "s: dead reckoning at full speed, then slowing to a stop"),
    Param("recap_interval", str, "", "s between CONTACTS_RECAP postings (off: none; default 1)"),
    Param("contacts_recap_interval", str, "", "older name of recap_interval"),
    Param("range_report_timeout", float, 10.0, "s a BCM_REPORT_REQUEST lasts without a repeat", lo=0.0),
    Param("range_report_maxsize", int, 20, "contacts in a range report at most", lo=0),
    Param("contact_local_coords", str, "verbatim", "verbatim, lazy_lat_lon or force_lat_lon (x/y from LAT/LON)"),
    Param("post_closest_range", bool, False, "CONTACT_CLOSEST_RANGE"),
    Param("post_closest_relbng", bool, False, "CONTACT_CLOSEST_RELBNG"),
    Param("post_all_ranges", bool, False, "CONTACT_RANGES"),
    Param("alert_verbose", bool, False, "ALERT_VERBOSE on every alert change"),
    Param("hold_alerts_for_helm", bool, False, "no alerts until the helm has been in DRIVE"),
    Param("ownship_group", str, "", "accepted"),
    Param("ownship_type", str, "", "accepted"),
    *(Param(key, float, None, "pBasicContactMgr: m, for alerts that give no range", lo=0.0)
      for key in BASIC_RANGE_KEYS),
    *(Param(key, float, None, "pBasicContactMgr: m, CPA range for alerts that give none", lo=0.0)
      for key in BASIC_CPA_KEYS),
    *(Param(key, str, "", "accepted for C++ missions, drawn or logged there: not acted on here")
      for key in sorted(NOT_IMPLEMENTED_KEYS - set(BASIC_RANGE_KEYS + BASIC_CPA_KEYS))),
)
INPUTS = ("NODE_REPORT", "BCM_ALERT_REQUEST", "BCM_REPORT_REQUEST", "BCM_DISPLAY_RADII", "NAV_X", "NAV_Y",
          "NAV_SPEED", "NAV_HEADING", "IVPHELM_STATE")


class ContactMgr(MachineApp):
    """pContactMgrV20: keeps the contacts heard in NODE_REPORT and posts alerts about them.

    Each alert (an `alert = id=..` line, or BCM_ALERT_REQUEST mail from the helm's
    templating behaviours) posts its on-flags once when a contact comes within range and its
    off-flags once when it leaves; `$[VNAME]`, `$[X]`, `$[GROUP]`, ... in a flag are the contact's.
    The usual one, `var=CONTACT_INFO, val="name=avd_$[VNAME] # contact=$[VNAME]"`, is what makes
    the helm spawn an avoidance behaviour per contact. The app also posts CONTACTS_LIST,
    CONTACT_CLOSEST, CONTACTS_RECAP, CONTACTS_ALERTED, CONTACTS_RETIRED and, when asked, the
    closest range and bearing and all ranges. Also answers to the name pBasicContactMgr.
    """

    default_name = "pContactMgrV20"
    parameters = CONTACT_MGR_PARAMS
    inputs = INPUTS
    basic = False   # read the block as pBasicContactMgr does
    example_config = """\
ProcessConfig = pContactMgrV20
{
  AppTick   = 4
  CommsTick = 4

  // Alerts (repeatable; lines with the same id add up). Usually the helm sends them instead,
  // as BCM_ALERT_REQUEST mail from a behaviour with templating = spawn.
  alert = id=avd, var=CONTACT_INFO, val="name=avd_$[VNAME] # contact=$[VNAME]"
  alert = id=avd, alert_range=80, cpa_range=100     // metres (cpa_range >= alert_range)
  alert = id=say, on_flag=SAY_MOOS=hello, off_flag=SAY_MOOS=bye, match_type=kayak

  // Contacts ignored or required, for every alert (comma lists; regions are polygons)
  ignore_name   = henry,gilda
  match_group   = bravo
  ignore_type   = buoy
  match_region  = pts={60,-40:60,-160:150,-160:150,-40}
  strict_ignore = true            // an ignore list also drops contacts that do not say

  contact_max_age     = 60        // s since the last report before a contact is retired
  max_retired_history = 5         // names kept in CONTACTS_RETIRED
  reject_range        = 2000      // m; contacts farther are retired (off: never)
  max_contacts        = 500
  decay               = 15,30     // s: dead reckoning at full speed, then slowing to a stop

  recap_interval       = 1        // s between CONTACTS_RECAP postings (off: none)
  range_report_timeout = 10       // s a BCM_REPORT_REQUEST lasts without a repeat
  range_report_maxsize = 20

  contact_local_coords = verbatim // verbatim | lazy_lat_lon | force_lat_lon (x/y from LAT/LON)
  post_closest_range   = false    // CONTACT_CLOSEST_RANGE
  post_closest_relbng  = false    // CONTACT_CLOSEST_RELBNG
  post_all_ranges      = false    // CONTACT_RANGES
  alert_verbose        = false    // ALERT_VERBOSE on every alert change
  hold_alerts_for_helm = false    // no alerts until the helm has been in DRIVE
}
"""
    interface = """\
SUBSCRIPTIONS:
  NODE_REPORT        = NAME=alpha,X=51.7,Y=-35.5,SPD=2.0,HDG=118.8,TYPE=kayak,GROUP=blue,TIME=...
  BCM_ALERT_REQUEST  = id=avd, var=CONTACT_INFO, val="name=avd_$[VNAME] # contact=$[VNAME]",
                       alert_range=80, cpa_range=100
  BCM_REPORT_REQUEST = var=CONTACTS_50, range=50[, group=.., type=.., refresh=true]
  NAV_X, NAV_Y, NAV_HEADING, NAV_SPEED   ownship
  IVPHELM_STATE      = DRIVE   (releases alerts held by hold_alerts_for_helm)
  BCM_DISPLAY_RADII  (accepted; radii are not drawn)
PUBLICATIONS:
  the alerts' flags, e.g. CONTACT_INFO = name=avd_henry # contact=henry
  CONTACTS_LIST         = delta,gus,henry            (on change)
  CONTACTS_ALERTED      = (delta,avd)(henry,avd)     (on change)
  CONTACTS_COUNT        = 2   (alerted contact/alert pairs, on change)
  CONTACTS_RETIRED      = bravo,foxtrot              (on change)
  CONTACTS_RECAP        = vname=delta,range=193.10,age=11.30 # vname=gus,...   (every recap_interval)
  CONTACT_CLOSEST       = henry, CONTACT_CLOSEST_TIME = <MOOS time>   (on change)
  CONTACT_CLOSEST_RANGE = 23   CONTACT_CLOSEST_RELBNG = 344   (whole numbers, if enabled, on change)
  CONTACT_RANGES        = 23.1,63.2,77.5             (if enabled, every iteration)
  ALERT_VERBOSE         = contact=henry,alert_id=avd,off-->alerted,...   (if enabled)
  <var> of each BCM_REPORT_REQUEST = the contacts within its range
"""

    def on_startup(self) -> None:
        params = read_params(self.config, lambda cfg: ContactMgrParams.from_config(cfg, self.basic))
        not_acted_on = NOT_IMPLEMENTED_KEYS - (set(BASIC_RANGE_KEYS + BASIC_CPA_KEYS) if self.basic else set())
        ignored = sorted({e.key.lower() for e in self.config.entries} & not_acted_on)
        if ignored:
            log.warning("%s: parameters accepted but not acted on (display/logging only): %s", self.name, ", ".join(ignored))
        ownship = (self.mission.community if self.mission is not None else "") or "unknown"
        try:
            self.machine = ContactManager(ownship, params, mission_grid(self.mission))
        except AlertError as exc:
            entry = next((e for e in self.config.entries if e.key.lower() == "alert" and e.value == exc.text), None)
            raise (entry.source.error(str(exc)) if entry is not None else exc) from None

    def status_fields(self) -> dict:
        return {"contacts": len(self.machine.contacts), "alerts": len(self.machine.alerts),
                "alerted": len(self.machine.alerted)}


class BasicContactMgr(ContactMgr):
    """pBasicContactMgr: the older contact manager, for older missions; the same app as pContactMgrV20
    reading the `ProcessConfig = pBasicContactMgr` block, with that app's two differences: an alert
    that gives no range uses `default_alert_range` / `default_cpa_range` (1000 m each; also spelt
    alert_range / alert_cpa_range), alerts may say `range=` and `range_cpa=`, and contacts are kept
    for `contact_max_age` = 3600 s.

    Keeps the contacts heard in NODE_REPORT, posts CONTACTS_LIST, CONTACT_CLOSEST, CONTACTS_RECAP,
    ... and the alerts (`alert = id=..` lines or BCM_ALERT_REQUEST mail) that make the helm spawn a
    behaviour per contact. See pContactMgrV20 for the rest.
    """

    default_name = "pBasicContactMgr"
    basic = True
    example_config = """\
ProcessConfig = pBasicContactMgr
{
  AppTick   = 4
  CommsTick = 4

  alert = id=avd, var=CONTACT_INFO
  alert = id=avd, val="name=avd_$[VNAME] # contact=$[VNAME]"
  alert = id=avd, range=80, range_cpa=95    // or alert_range= / cpa_range=

  default_alert_range = 1000   // m, for alerts that give no range (alias alert_range)
  default_cpa_range   = 1000   // m, likewise (aliases default_alert_range_cpa, alert_cpa_range)

  contact_max_age = 3600       // s
  decay           = 15,30
  contacts_recap_interval = 1  // s (alias of recap_interval)
  alert_verbose   = false
}
"""


main = ContactMgr.main
basic_main = BasicContactMgr.main
