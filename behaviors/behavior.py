"""The IvP behaviour base: general parameters, flags, conditions, duration, updates and macros.

The helm (helm.py) drives the life cycle; a behaviour type only adds its own parameters
(`set_param`) and its objective function (`on_run_state`). Spec: docs/spec/ivp-helm.md §2-3,
docs/spec/mission-files.md §2.5.
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass
from typing import Union

from moosdb_py.formats import FormatError, parse_pairs

from .domain import IvPDomain
from .geometry import fmt_num
from .flags import FLAG_KINDS, FlagError, FlagSpec, expand_macros, parse_flag
from .ivp_function import IvPFunction
from .logic import ConditionError, as_number, parse_behavior_condition
from .parameters import (BOOLEAN, NON_NEGATIVE, TEXT, ParamSpec, Parser, accepted, attr, collect, parse_number,
                         unique_specs)

Value = Union[float, str]
# Flags the helm posts every time (not deduplicated); spec docs/spec/ivp-helm.md §1.3.
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



@dataclass(slots=True)
class Post:
    var: str
    value: Value
    repeatable: bool = False
    key: str = ""  # sub-key for deduplication, so two posts of one variable do not shadow each other


def apply_visual_hints(hints: dict[str, str], value: str) -> None:
    """`visual_hints = vertex_color=red, edge_size=2`: lines accumulate; keys this behaviour does not
    draw with are ignored, as MOOS-IvP does; a size must be a number >= 0."""
    try:
        pairs = parse_pairs(value)
    except FormatError as exc:
        raise ValueError(f"visual_hints: {exc}") from None
    for key, val in pairs.items():
        if key not in hints:
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

    def reset_requested(self, info: InfoBuffer) -> bool:
        """`duration_reset = VAR=value` and VAR was posted that value this iteration."""
        return bool(self.reset_var) and any(str(v) == self.reset_value or as_number(self.reset_value) == v
                                            for v in info.deltas.get(self.reset_var, []))

    def run(self, now: float, was_running: bool) -> bool:
        """Count one running iteration; True when the limit is reached."""
        if self.started is None:
            self.reset(now)
        elif not self.idle_decay and was_running:
            self.running_time += now - (self.last_tick or now)
        return self.limit is not None and self.elapsed(now) >= self.limit

    def remaining(self, now: float) -> float:
        return round(max(self.limit - self.elapsed(now), 0.0), 2)


def flag_param(kind: str, *aliases: str) -> ParamSpec:
    """A flag list (`kind = VAR = value [[if] condition]`); `clearall` empties it."""
    def add(bhv: "IvPBehavior", value: str) -> None:
        try:
            flag = parse_flag(value)
        except FlagError as exc:
            raise ValueError(str(exc)) from None
        if flag is None:
            bhv.flags[kind] = []
        else:
            bhv.flags.setdefault(kind, []).append(flag)
    return ParamSpec((kind, *aliases), Parser("flag", lambda value, key: value), add, None,
                     "`VAR = value [[if] condition]`, repeatable; `clearall` empties the list")


def _duration_limit(value: str, key: str) -> float | None:
    return None if value.strip().lower() in ("no-time-limit", "-1") else parse_number(value, key, 0)


def _duration_reset(value: str, key: str) -> tuple[str, str]:
    var, sep, val = value.partition("=")
    if not sep or not var.strip():
        raise ValueError(f"duration_reset must be VAR=value, got '{value}'")
    return var.strip(), val.strip()


def _set_duration_reset(bhv: "IvPBehavior", var_value: tuple[str, str]) -> None:
    bhv.duration.reset_var, bhv.duration.reset_value = var_value


def _nostarve(value: str, key: str) -> tuple[list[str], float]:
    parts = [p.strip() for p in value.split(",")]
    if len(parts) < 2:
        raise ValueError(f"{key} must be VAR1,...,secs, got '{value}'")
    return parts[:-1], parse_number(parts[-1], key, 0)


def _post_mapping(value: str, key: str) -> tuple[str, str]:
    old, sep, new = value.partition(",")
    if not sep:
        raise ValueError(f"post_mapping must be OLDVAR,NEWVAR, got '{value}'")
    return old.strip(), new.strip()


def _condition(value: str, key: str):
    try:
        return parse_behavior_condition(value)
    except ConditionError as exc:
        raise ValueError(str(exc)) from None


class IvPBehavior:
    """A behaviour instance; subclasses set `type_name`, `default_name`, `info_vars`, declare their
    parameters (`params`, `@param`) and override the hooks.

    The behaviour owns its life cycle, as MOOS-IvP's IvPBehavior does: each iteration the helm calls
    `tick(now)` (updates, conditions, duration, state, flags, BHV_STATUS; the objective function or
    None), then `take_posts()`; a template's copy is named by `spawn_as(suffix)`."""

    type_name = "BHV_Base"
    default_name = "bhv"
    info_vars: tuple[str, ...] = ()
    domain_vars: tuple[str, ...] = ("course", "speed")
    uses_contacts = False    # reads other vehicles' NODE_REPORTs (`<NAME>_NAV_*`) from the info buffer
    parameters: dict[str, ParamSpec] = {}
    attr_specs: dict[str, ParamSpec] = {}
    params: tuple[ParamSpec, ...] = (
        ParamSpec(("name", "descriptor"), TEXT, lambda b, v: setattr(b, "name", v), None,
                  "behaviour name (a spawned copy: the template's name + suffix)"),
        attr(("pwt", "priority", "priwt"), "pwt", NON_NEGATIVE, "100", "priority weight of the objective function"),
        ParamSpec(("condition",), Parser("condition", _condition), lambda b, c: b.conditions.append(c), None,
                  "run condition, repeatable; all must hold"),
        *(flag_param(kind, *(("spawnx_flag",) if kind == "spawnxflag" else ())) for kind in FLAG_KINDS),
        attr("updates", "updates_var", TEXT, "", doc="variable carrying `param=value # param=value` updates"),
        attr("perpetual", "perpetual", BOOLEAN, "false", "completing posts the endflags but does not end it"),
        ParamSpec(("duration",), Parser("seconds \\| no-time-limit", _duration_limit),
                  lambda b, v: setattr(b.duration, "limit", v), None, "complete after running this long"),
        ParamSpec(("duration_status",), TEXT, lambda b, v: setattr(b.duration, "status_var", v), None,
                  "variable for the seconds left"),
        ParamSpec(("duration_idle_decay",), BOOLEAN, lambda b, v: setattr(b.duration, "idle_decay", v), "true",
                  "idle time counts against the duration"),
        ParamSpec(("duration_reset",), Parser("VAR=value", _duration_reset), _set_duration_reset, None,
                  "restart the duration when VAR is posted this value"),
        attr(("nostarve", "no_starve"), "nostarve", Parser("VAR,...,secs", _nostarve),
             doc="idle while one of the variables is older than secs"),
        ParamSpec(("post_mapping",), Parser("OLDVAR,NEWVAR", _post_mapping),
                  lambda b, v: b.post_mapping.__setitem__(*v), None, "rename a posted variable (`silent` drops it)"),
        attr("templating", "templating", Parser("word", lambda value, key: value.lower()), "",
             "`spawn`: a template, copied per `name=` update of its `updates` variable"),
        accepted(("comms_policy", "max_spawnings", "build_info", "precision"),
                 "accepted for compatibility; they tune features this helm does not have"),
    )

    def __init_subclass__(cls, inherit: tuple[str, ...] | None = None, **kwargs) -> None:
        """Build the type's parameter table; `inherit` limits what it takes from its parent type."""
        super().__init_subclass__(**kwargs)
        base = cls.__mro__[1]
        parent = base.parameters
        if inherit is not None:
            parent = {k: s for k, s in parent.items() if k in IvPBehavior.parameters or k in inherit}
        cls.parameters = collect(cls, parent)
        # Attributes keep their declared defaults even where a type does not take the parameter.
        cls.attr_specs = {**base.attr_specs, **{s.attr: s for s in unique_specs(cls.parameters) if s.attr}}

    def __init__(self, domain: IvPDomain, info: InfoBuffer, ownship: str = ""):
        self.domain, self.info, self.ownship = domain, info, ownship
        self.name = self.default_name
        self.conditions: list = []
        self.flags: dict[str, list[FlagSpec]] = {k: [] for k in FLAG_KINDS}
        self.duration = Duration()
        self.post_mapping: dict[str, str] = {}
        self.spawn_suffix = ""
        self.state = ""          # "", idle, running, active, completed
        self.completed = False
        self.posts: list[Post] = []
        self.last_update = ""
        self.good_updates = self.bad_updates = 0
        self.now = 0.0
        self.started = False     # the configflags and spawnxflags go out on the first iteration
        self._first_macro_time: float | None = None
        self._counter = 0
        self.run_started: float | None = None
        self.idle_started: float | None = None
        for name, spec in self.attr_specs.items():
            setattr(self, name, None if spec.default is None else spec.parse(spec.default, spec.name))

    # ---- configuration -------------------------------------------------------------
    @classmethod
    def spec_for(cls, key: str) -> ParamSpec | None:
        """The declaration of a `.bhv` key (a leading `_` is allowed on the general ones), or None."""
        key = key.strip().lower()
        return cls.parameters.get(key) or IvPBehavior.parameters.get(key.lstrip("_"))

    def apply(self, key: str, value: str) -> None:
        """Apply one `param = value`; raise ValueError for an unknown key or a bad value."""
        spec = self.spec_for(key)
        if spec is None:
            raise ValueError(f"unknown parameter '{key.strip().lower()}' for {self.type_name}")
        spec.apply(self, value.strip(), key.strip().lower())


    # ---- life cycle: what the helm calls ------------------------------------------------
    def spawn_as(self, suffix: str) -> None:
        """Make this fresh copy of a template the instance `<template name><suffix>`."""
        self.name, self.spawn_suffix, self.templating = self.name + suffix, suffix, ""

    def take_posts(self) -> list[Post]:
        posts, self.posts = self.posts, []
        return posts

    def tick(self, now: float) -> IvPFunction | None:
        """One helm iteration: updates, conditions, duration, state transitions with their flags
        and hooks, BHV_STATUS; returns the objective function when active."""
        self.now = now
        self._apply_updates(now)
        if not self.started:
            self.started = True
            self.post_flags("configflag")
            self.post_flags("spawnxflag")
        dur = self.duration
        if dur.reset_requested(self.info):
            dur.reset(now)
        prev = self.state
        failed = None
        lookup = self.info.get
        for c in self.conditions:     # a loop, not next() over a generator: every behaviour, every iteration
            if not c.evaluate(lookup):
                failed = c
                break
        if self.completed:
            state = "completed"
        elif failed is not None:
            state = "idle"
        else:
            state = "running"
            if dur.run(now, was_running=prev in ("running", "active")):
                self.set_complete()
                if self.completed:
                    state = "completed"
                else:
                    dur.reset(now)
            if state == "running" and self._starved(now):
                state = "idle"
        dur.last_tick = now
        self.on_every_state()
        fn = None
        if state == "idle":
            self._idle(prev)
        elif state == "running":
            fn = self._run(prev)
            if fn is not None:
                state = "active"
        if self.completed:
            state, fn = "completed", None
        self.state = state
        status = f"name={self.name}" + (f",pc={failed}" if failed is not None and state == "idle" else "")
        status += f",updates={self.good_updates}/{self.good_updates + self.bad_updates},state={state}"
        self.post("BHV_STATUS", status + (",pwt=%g" % fn.pwt if fn is not None else ""))
        return fn

    def _idle(self, prev: str) -> None:
        if prev != "idle":
            self.idle_started = self.now
            self.post_flags("idleflag")
            self.post_flags("inactiveflag")
            if prev in ("running", "active"):
                self.on_run_to_idle()
        self.on_idle_state()

    def _run(self, prev: str) -> IvPFunction | None:
        if prev in ("idle", ""):
            self.run_started = self.now
            if prev == "idle":
                self.on_idle_to_run()
        fn = self.on_run_state()
        if prev in ("idle", ""):
            self.post_flags("runflag")
        self.post_flags("runxflag")
        if self.duration.status_var and self.duration.limit is not None:
            self.post(self.duration.status_var, self.duration.remaining(self.now))
        if fn is not None and fn.has_nan():
            self.post("BHV_ERROR", f"{self.name}: objective function has NaN", repeatable=True)
            fn = None
        if fn is not None and fn.pwt <= 0:
            fn = None
        if fn is not None and prev != "active":
            self.post_flags("activeflag")
        elif fn is None and prev == "active":
            self.post_flags("inactiveflag")
        return fn

    def _starved(self, now: float) -> bool:
        if not self.nostarve:
            return False
        names, secs = self.nostarve
        return any(self.info.times.get(v) is None or now - self.info.times[v] > secs for v in names)

    def _apply_updates(self, now: float) -> None:
        """Each string posted to the `updates` variable this iteration, answered by IVPHELM_UPDATE_RESULT."""
        if not self.updates_var:
            return
        for raw in self.info.deltas.get(self.updates_var, []):
            text = str(raw).strip()
            if not text:
                continue
            low = text.lower()
            if text == self.last_update and not any(w in low for w in ("toggle", "engage", "mod")):
                result = "duplicate"
            else:
                result = self._apply_update_string(text)
            self.post("IVPHELM_UPDATE_RESULT",
                      f"bhv={self.name},var={self.updates_var},time={now:.2f},result={result},val={text}",
                      repeatable=True)

    def _apply_update_string(self, text: str) -> str:
        pairs = [p.partition("=") for p in text.split("#") if p.strip()]
        for key, _, value in pairs:
            if key.strip().lower() == "name" and value.strip() != (self.spawn_suffix or self.name):
                return "name_mismatch"
        bad = []
        for key, sep, value in pairs:
            if key.strip().lower() == "name":
                continue
            try:
                if not sep:
                    raise ValueError
                self.apply(key, value)
            except ValueError:
                bad.append(key.strip())
        if bad:
            self.post("BHV_WARNING", f"Faulty update for behavior: {self.name}. Bad parameter(s): {','.join(bad)}",
                      repeatable=True)
            self.bad_updates += 1
            return "param_error"
        self.good_updates += 1
        self.last_update = text
        self.post_flags("configflag")
        self.on_update_applied()
        return "success"

    def needed_domain_vars(self) -> tuple[str, ...]:
        return self.domain_vars

    def delta_vars(self) -> list[str]:
        """Variables whose every post this iteration matters (updates, duration resets), not just the last."""
        return [v for v in (self.updates_var, self.duration.reset_var) if v]

    def run_condition_vars(self) -> list[str]:
        """The variables of the run conditions (IVPHELM_STATEVARS)."""
        return [v for c in self.conditions for v in c.variables()]

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
    def on_helm_start(self) -> None:
        """Called once when the helm starts, templates included (e.g. to request contact alerts)."""

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


IvPBehavior.parameters = collect(IvPBehavior, {})
IvPBehavior.attr_specs = {s.attr: s for s in unique_specs(IvPBehavior.parameters) if s.attr}
