"""The IvP behaviour base: general parameters, flags, conditions, duration, updates and macros.

The helm (helm.py) drives the life cycle; a behaviour type only adds its own parameters
(`set_param`) and its objective function (`on_run_state`). Spec: ivp-helm.md §2-3,
mission-files.md §2.5.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass
from typing import Union

from .domain import IvPDomain
from .geometry import fmt_num
from .flags import FLAG_KINDS, FlagError, FlagSpec, expand_macros, parse_flag
from .ivp_function import IvPFunction
from .logic import ConditionError, as_number, parse_behavior_condition

Value = Union[float, str]
# Flags the helm posts every time (not deduplicated); spec ivp-helm.md §1.3.
REPEATABLE_FLAGS = {"runflag", "runxflag", "idleflag", "activeflag", "inactiveflag", "endflag", "cycleflag"}


class InfoBuffer:
    """The helm's view of the MOOSDB: latest value and time per variable, plus this iteration's deltas."""

    def __init__(self) -> None:
        self.values: dict[str, Value] = {}
        self.times: dict[str, float] = {}
        self.deltas: dict[str, list[Value]] = {}
        # Only variables whose every post matters (updates, duration resets) keep deltas, so a
        # parked helm that never clears them does not pile up navigation history.
        self.delta_vars: set[str] = set()

    def set(self, var: str, value: Value, time: float) -> bool:
        """Store a value; a variable keeps the type (double or string) it was first given."""
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = float(value)
        old = self.values.get(var)
        if old is not None and isinstance(old, float) != isinstance(value, float):
            return False
        self.values[var] = value
        self.times[var] = time
        if var in self.delta_vars:
            self.deltas.setdefault(var, []).append(value)
        return True

    def get(self, var: str) -> Value | None:
        return self.values.get(var)

    def number(self, var: str) -> float | None:
        v = self.values.get(var)
        return v if isinstance(v, float) else None

    def clear_deltas(self) -> None:
        self.deltas.clear()


@dataclass
class Post:
    var: str
    value: Value
    repeatable: bool = False
    key: str = ""  # sub-key for deduplication, so two posts of one variable do not shadow each other


def parse_bool(value: str, what: str) -> bool:
    low = value.strip().lower()
    if low not in ("true", "false"):
        raise ValueError(f"{what} must be true or false, got '{value}'")
    return low == "true"


def parse_number(value: str, what: str, minimum: float | None = None) -> float:
    number = as_number(value)
    if number is None or (minimum is not None and number < minimum):
        bound = f" >= {minimum:g}" if minimum is not None else ""
        raise ValueError(f"{what} must be a number{bound}, got '{value}'")
    return number


def apply_visual_hints(hints: dict[str, str], value: str) -> None:
    """`visual_hints = vertex_color=red, edge_size=2`: lines accumulate; keys this behaviour does not
    draw with are ignored, as MOOS-IvP does; a size must be a number >= 0."""
    for item in value.split(","):
        key, sep, val = (part.strip() for part in item.partition("="))
        key = key.lower()
        if not sep or key not in hints:
            continue
        if key.endswith("size"):
            val = fmt_num(parse_number(val, f"visual_hints {key}", 0))
        hints[key] = val


def hint_fields(hints: dict[str, str], *keys: str) -> str:
    """`,key=value` for each hint named, in the order given."""
    return "".join(f",{k}={hints[k]}" for k in keys)


@dataclass
class Duration:
    limit: float | None = None
    idle_decay: bool = True
    status_var: str = ""
    reset_var: str = ""
    reset_value: str = ""
    started: float | None = None
    running_time: float = 0.0
    last_tick: float | None = None

    def elapsed(self, now: float) -> float:
        if self.started is None:
            return 0.0
        return now - self.started if self.idle_decay else self.running_time

    def reset(self, now: float) -> None:
        self.started, self.running_time, self.last_tick = now, 0.0, now


class IvPBehavior:
    """A behaviour instance; subclasses set `type_name`, `default_name`, `info_vars` and override hooks."""

    type_name = "BHV_Base"
    default_name = "bhv"
    info_vars: tuple[str, ...] = ()
    domain_vars: tuple[str, ...] = ("course", "speed")

    def __init__(self, domain: IvPDomain, info: InfoBuffer, ownship: str = ""):
        self.domain, self.info, self.ownship = domain, info, ownship
        self.name = self.default_name
        self.pwt = 100.0
        self.conditions: list = []
        self.flags: dict[str, list[FlagSpec]] = {k: [] for k in FLAG_KINDS}
        self.updates_var = ""
        self.perpetual = False
        self.duration = Duration()
        self.nostarve: tuple[list[str], float] | None = None
        self.post_mapping: dict[str, str] = {}
        self.templating = ""
        self.spawn_suffix = ""
        self.state = ""          # "", idle, running, active, completed
        self.completed = False
        self.posts: list[Post] = []
        self.last_update = ""
        self.good_updates = self.bad_updates = 0
        self.now = 0.0
        self._first_macro_time: float | None = None
        self._counter = 0
        self.run_started: float | None = None
        self.idle_started: float | None = None

    # ---- configuration -------------------------------------------------------------
    def set_param(self, key: str, value: str) -> bool:
        """Behaviour-specific parameter; return False when the key is not one of ours."""
        return False

    def set_general(self, key: str, value: str) -> bool:
        """Parameters every behaviour accepts (mission-files.md §2.5); raises ValueError on bad values."""
        key = key.lstrip("_")
        if key in ("name", "descriptor"):
            self.name = value
        elif key in ("pwt", "priority", "priwt"):
            self.pwt = parse_number(value, key, 0)
        elif key == "condition":
            try:
                self.conditions.append(parse_behavior_condition(value))
            except ConditionError as exc:
                raise ValueError(str(exc)) from None
        elif key in FLAG_KINDS or key == "spawnx_flag" or self.is_flag_kind(key):
            kind = "spawnxflag" if key == "spawnx_flag" else key
            try:
                flag = parse_flag(value)
            except FlagError as exc:
                raise ValueError(str(exc)) from None
            if flag is None:
                self.flags[kind] = []
            else:
                self.flags.setdefault(kind, []).append(flag)
        elif key == "updates":
            self.updates_var = value
        elif key == "perpetual":
            self.perpetual = parse_bool(value, key)
        elif key == "duration":
            low = value.lower()
            self.duration.limit = None if low in ("no-time-limit", "-1") else parse_number(value, key, 0)
        elif key == "duration_status":
            self.duration.status_var = value
        elif key == "duration_idle_decay":
            self.duration.idle_decay = parse_bool(value, key)
        elif key == "duration_reset":
            var, sep, val = value.partition("=")
            if not sep or not var.strip():
                raise ValueError(f"duration_reset must be VAR=value, got '{value}'")
            self.duration.reset_var, self.duration.reset_value = var.strip(), val.strip()
        elif key in ("nostarve", "no_starve"):
            parts = [p.strip() for p in value.split(",")]
            self.nostarve = (parts[:-1], parse_number(parts[-1], key, 0)) if len(parts) > 1 else None
            if self.nostarve is None:
                raise ValueError(f"{key} must be VAR1,...,secs, got '{value}'")
        elif key == "post_mapping":
            old, sep, new = value.partition(",")
            if not sep:
                raise ValueError(f"post_mapping must be OLDVAR,NEWVAR, got '{value}'")
            self.post_mapping[old.strip()] = new.strip()
        elif key == "templating":
            self.templating = value.lower()
        elif key in ("comms_policy", "max_spawnings", "build_info", "precision"):
            pass  # accepted for compatibility; they only tune features this helm does not have
        else:
            return False
        return True

    def is_flag_kind(self, key: str) -> bool:
        """Behaviour types with extra flag lists (Waypoint: cycleflag, wptflag) extend this."""
        return False

    def apply(self, key: str, value: str, *, general_first: bool = True) -> None:
        """Apply one `param = value`; raise ValueError when neither setter accepts it."""
        key = key.strip().lower()
        value = value.strip()
        order = (self.set_general, self.set_param) if general_first else (self.set_param, self.set_general)
        for setter in order:
            if setter(key, value):
                return
        raise ValueError(f"unknown parameter '{key}' for {self.type_name}")

    def needed_domain_vars(self) -> tuple[str, ...]:
        return self.domain_vars

    def condition_vars(self) -> list[str]:
        names = [v for c in self.conditions for v in c.variables()]
        for flags in self.flags.values():
            names += [v for f in flags if f.condition for v in f.condition.variables()]
        if self.updates_var:
            names.append(self.updates_var)
        if self.duration.reset_var:
            names.append(self.duration.reset_var)
        if self.nostarve:
            names += self.nostarve[0]
        if any(f.dest.lstrip("#").rstrip("+").lower() == "group" for fl in self.flags.values() for f in fl):
            names.append(self.own_group_var())
        return names + list(self.info_vars)

    # ---- posting --------------------------------------------------------------------
    def post(self, var: str, value: Value, key: str = "", repeatable: bool = False) -> None:
        mapped = self.post_mapping.get(var, var)
        if mapped.lower() == "silent":
            return
        self.posts.append(Post(mapped, value, repeatable, key))

    def post_flags(self, kind: str) -> None:
        for flag in self.flags.get(kind, []):
            if not flag.holds(self.info.get):
                continue
            value = expand_macros(flag.value, self.macro)
            repeatable = kind in REPEATABLE_FLAGS
            if flag.dest:
                self.post("NODE_MESSAGE_LOCAL", self.node_message(flag.dest, flag.var, value),
                          key=kind + flag.var, repeatable=repeatable)
            if not flag.dest or flag.dest.endswith("+"):
                self.post(flag.var, value, key=kind, repeatable=repeatable)

    def own_group_var(self) -> str:
        return f"{self.ownship.upper()}_NAV_GROUP"

    def node_message(self, dest: str, var: str, value: Value) -> str:
        """A flag for other vehicles (`#all`, `#group`, `#group=red`, `#abe`; `+` = also local), in the
        NODE_MESSAGE_LOCAL format uFldNodeBroker/uFldNodeComms carry: src_node, dest_node, dest_group,
        var_name, double_val | string_val (quoted when it holds a comma)."""
        dest = dest.lstrip("#").rstrip("+")
        group = ""
        if dest.lower() == "group":
            dest, group = "all", str(self.info.get(self.own_group_var()) or "")
        elif dest.lower().startswith("group="):
            dest, group = "all", dest.partition("=")[2]
        fields = [f"src_node={self.ownship}", f"dest_node={dest}"] + ([f"dest_group={group}"] if group else [])
        fields.append(f"var_name={var}")
        if isinstance(value, float):
            fields.append(f"double_val={fmt_num(value, 6)}")
        elif "," in value and not (value.startswith('"') and value.endswith('"')):
            fields.append(f'string_val="{value}"')
        else:
            fields.append(f"string_val={value}")
        return ",".join(fields)

    def macro(self, name: str) -> Value | None:
        """Value of a `$[NAME]` macro, or None to leave it as typed."""
        n = name.upper()
        if n == "OWNSHIP":
            return self.ownship
        if n == "BHVNAME":
            return self.name
        if n == "BHVTYPE":
            return self.type_name
        if n == "PWT":
            return self.pwt
        if n == "UTC":
            return _time.time()
        nav = {"OSX": "NAV_X", "OSY": "NAV_Y", "OSH": "NAV_HEADING", "OSV": "NAV_SPEED"}
        if n in nav:
            return self.info.number(nav[n])
        if n == "DUR_RUN_TIME":
            return round(self.now - self.run_started, 3) if self.run_started is not None else 0.0
        if n == "DUR_IDLE_TIME":
            return round(self.now - self.idle_started, 3) if self.idle_started is not None else 0.0
        if n == "NOW":
            if self._first_macro_time is None:
                self._first_macro_time = self.now
            return round(self.now - self._first_macro_time, 3)
        if n.startswith("CTR"):
            self._counter += 1
            return float(self._counter)
        return None

    # ---- life cycle hooks (subclasses) ------------------------------------------------
    def on_every_state(self) -> None:
        pass

    def on_idle_state(self) -> None:
        pass

    def on_idle_to_run(self) -> None:
        pass

    def on_run_to_idle(self) -> None:
        pass

    def on_run_state(self) -> IvPFunction | None:
        return None

    def on_update_applied(self) -> None:
        """Called after a successful update, e.g. to post BHV_SETTINGS."""

    def set_complete(self) -> None:
        """Post the endflags; a non-perpetual behaviour then stops for good."""
        self.post_flags("endflag")
        if not self.perpetual:
            self.completed = True

    def nav(self) -> tuple[float, float, float | None, float | None] | None:
        """Ownship x, y, heading, speed; None (and a BHV_ERROR post) if NAV_X/NAV_Y are unknown."""
        x, y = self.info.number("NAV_X"), self.info.number("NAV_Y")
        if x is None or y is None:
            self.post("BHV_ERROR", f"{self.name}: No ownship NAV_X/NAV_Y in info_buffer", repeatable=True)
            return None
        return x, y, self.info.number("NAV_HEADING"), self.info.number("NAV_SPEED")
