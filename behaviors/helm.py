"""The helm engine: modes, behaviour life cycles, post deduplication, solving and all-stop.

Pure logic with no MOOS: feed it mail (`on_mail`) and call `iterate(now)`; it returns the posts to
send as (var, value, source_aux) triples. `helm_app.HelmIvP` is the thin MOOS shell around it.
Spec: docs/spec/ivp-helm.md §1-3.
"""
from __future__ import annotations

import time as _time
from time import perf_counter
from typing import Union

from moosdb_py.source import MissionFileError

from .behavior import InfoBuffer, IvPBehavior, Post
from .bhv_file import BehaviorSpec, BhvFile
from .contacts import node_report_values
from .domain import IvPDomain
from .ivp_function import IvPFunction
from .logic import as_number
from .registry import PluginError, behavior_class, behavior_types, known_type_names
from .solver import missing_decisions, solve

Value = Union[float, str]
HelmPost = tuple[str, Value, str]
BEHAVIOR_TYPES = behavior_types()   # what moos-lint looks types up in (registry.behavior_class is the live view)
ALWAYS_SUBSCRIBED = ("NAV_X", "NAV_Y", "NAV_HEADING", "NAV_SPEED", "NAV_DEPTH", "MOOS_MANUAL_OVERRIDE",
                     "MOOS_MANUAL_OVERIDE", "DB_CLIENTS", "RESTART_HELM", "BHV_ABLE_FILTER", "HELM_MAP_CLEAR",
                     "IVPHELM_STATE")
EMPTY_DECISIONS = ("NothingToDo", "NoGoalBehavior")
TIMING_FIELDS = ("create_time", "solve_time", "loop_time", "max_create_time", "max_solve_time", "max_loop_time")
SUMMARY_KEYS = ("ofnum", "warnings", *TIMING_FIELDS, "halted", "active_goal", "modes", "active_bhvs", "running_bhvs",
                "idle_bhvs", "completed_bhvs")     # IVPHELM_SUMMARY's fields in order, then one var= per decision variable


def build_behavior(spec: BehaviorSpec, domain: IvPDomain, info: InfoBuffer, ownship: str) -> IvPBehavior:
    """Make and configure a behaviour from its block; errors name the .bhv file and line."""
    try:
        cls = behavior_class(spec.type)
    except PluginError as exc:
        raise MissionFileError(spec.file, spec.line, str(exc)) from None
    if cls is None:
        known = ", ".join(known_type_names()) or "none: the behaviors.bhv entry points are missing, reinstall the package"
        raise MissionFileError(spec.file, spec.line, f"unknown behavior type '{spec.type}' (this helm has {known})")
    bhv = cls(domain, info, ownship)
    for p in spec.params:
        try:
            bhv.apply(p.key, p.value)
        except ValueError as exc:
            raise p.error(f"{spec.type} '{spec.name}': {exc}") from None
    missing = [n for n in bhv.needed_domain_vars() if n not in domain]
    if missing:
        raise MissionFileError(spec.file, spec.line,
                               f"{spec.type} '{bhv.name}' needs domain variable(s) {', '.join(missing)}")
    return bhv


class Helm:
    """One vehicle's helm: behaviours from .bhv files over a decision domain."""

    def __init__(self, bhv_files: list[BhvFile], domain: IvPDomain, ownship: str = "", *,
                 app_name: str = "pHelmIvP", active_start: bool = False, allow_park: bool = True,
                 park_on_allstop: bool = False, helm_prefix: str = ""):
        self.domain, self.ownship, self.app_name = domain, ownship, app_name
        self.allow_park, self.park_on_allstop, self.helm_prefix = allow_park, park_on_allstop, helm_prefix
        self.info = InfoBuffer()
        self.grid = None   # the mission's LocalGrid: places NODE_REPORTs that give only LAT/LON
        self.modes = [m for f in bhv_files for m in f.modes]
        self.initializes = [i for f in bhv_files for i in f.initializes]
        self.behaviors: list[IvPBehavior] = []
        self.templates: dict[str, tuple[BehaviorSpec, IvPBehavior]] = {}
        for f in bhv_files:
            for spec in f.behaviors:
                bhv = build_behavior(spec, domain, self.info, ownship)
                if bhv.templating == "spawn":
                    self.templates[bhv.name] = (spec, bhv)
                else:
                    self.behaviors.append(bhv)
        self._track_deltas()
        self.status = "DRIVE" if active_start else "PARK"
        self.last_state = ""
        self.iteration = 0
        self.start_time: float | None = None
        self.allstop_status = ""
        self.last_sent: dict[str, Value] = {}
        self.mode_values: dict[str, Value] = {}
        self.seen_own_state = False
        self.deferred_done = False
        self.decision: dict[str, float] = {}
        self.summary_values: list[str] = []     # IVPHELM_SUMMARY's fields as last posted (SUMMARY_KEYS, then var=)
        self._grouped: tuple = (None, None, {})   # the behaviours' names and states, and their groups' texts
        self._modes_text: str | None = None       # IVPHELM_SUMMARY's modes field (None: mode_values changed)
        self.bhv_lists: dict[str, str] = {}
        self.last_map_clear = -1e9
        self.nav_grace = 5.0
        self.hold_on_apps: list[str] = []
        self.config_warnings: list[str] = []   # each one means MALCONFIG
        self.run_warnings: list[str] = []      # nav grace, holds: reported once each
        # IVPHELM_SUMMARY's timing fields, in its order: the latest create/solve/loop times and their maxima.
        self.timing = dict.fromkeys(TIMING_FIELDS, 0.0)
        self.nav_seen = False    # every NAV_* needed has been received
        self.nav_needed = ["NAV_X", "NAV_Y", "NAV_HEADING", "NAV_SPEED"] + (["NAV_DEPTH"] if "depth" in domain else [])
        self.desired_names = {v.name: self._desired_name(v.name) for v in domain.vars}

    def _track_deltas(self) -> None:
        for bhv in self.behaviors + [t for _, t in self.templates.values()]:
            self.info.delta_vars.update(bhv.delta_vars())

    # ---- subscriptions and startup ---------------------------------------------------
    def subscriptions(self) -> list[str]:
        names = list(ALWAYS_SUBSCRIBED)
        names += [v for m in self.modes for c in m.conditions for v in c.variables()]
        names += [i.var for i in self.initializes if i.deferred]
        for bhv in self.behaviors + [t for _, t in self.templates.values()]:
            names += bhv.condition_vars()
            if bhv.uses_contacts:
                names.append("NODE_REPORT")
        return list(dict.fromkeys(names))

    def startup(self, now: float) -> list[HelmPost]:
        """Initialize posts, the domain and mode-set descriptions, and IVPHELM_REGISTER lines."""
        self.start_time = now
        out: list[HelmPost] = []
        for init in self.initializes:
            if not init.deferred:
                self.info.set(init.var, init.value, now)
                out.append((init.var, init.value, "HELM_VAR_INIT"))
        out.append(("IVPHELM_DOMAIN", self.domain.describe(), ""))
        modeset = "#".join(f"{m.var}={m.value}{'@' + m.prefix if m.prefix else ''}" for m in self.modes)
        out.append(("IVPHELM_MODESET", modeset, ""))
        out.append(("IVPHELM_STATEVARS", ",".join(self.state_vars()), ""))
        out += [("IVPHELM_REGISTER", v, "") for v in self.subscriptions()]
        for bhv in self.behaviors + [t for _, t in self.templates.values()]:
            bhv.on_helm_start()
            out += [(p.var, p.value, "") for p in bhv.take_posts()]
        return out

    def state_vars(self) -> list[str]:
        """Variables the behaviours' states depend on: mode and behaviour conditions."""
        names = [v for m in self.modes for c in m.conditions for v in c.variables()]
        for bhv in self.behaviors + [t for _, t in self.templates.values()]:
            names += bhv.run_condition_vars()
        return list(dict.fromkeys(names))

    # ---- mail -------------------------------------------------------------------------
    def on_mail(self, var: str, value: Value | bytes, time: float, source: str = "") -> None:
        if isinstance(value, bytes):
            return  # binary mail means nothing to conditions or behaviours
        if var == "IVPHELM_STATE":
            if source == self.app_name:
                self.seen_own_state = True
            elif str(value).upper() != "STANDBY" and self.status in ("PARK", "DRIVE"):
                self.status = "DISABLED"
            return
        if var in ("MOOS_MANUAL_OVERRIDE", "MOOS_MANUAL_OVERIDE"):
            text = str(value).strip().lower()
            if self.status in ("PARK", "DRIVE"):
                if text == "false":
                    self.status = "DRIVE"
                elif text == "true" and self.allow_park:
                    self.status = "PARK"
        if var == "NODE_REPORT":
            for name, field in (node_report_values(str(value), self.grid) or {}).items():
                self.info.set(name, field, time)
        if var == "HELM_MAP_CLEAR" and time - self.last_map_clear >= 2.0:
            self.last_map_clear = time
            self.last_sent.clear()
        self.info.set(var, value, time)

    def malconfig(self, warning: str) -> None:
        self.config_warnings.append(warning)
        self.status = "MALCONFIG"

    def _warn_once(self, warning: str) -> None:
        if warning not in self.run_warnings:
            self.run_warnings.append(warning)

    def _holding(self, now: float) -> bool:
        """Nav hold (NAV_* not all seen yet) and hold_on_apps (apps not all in DB_CLIENTS)."""
        if self.nav_seen and not self.hold_on_apps:     # the info buffer keeps every variable once set
            return False
        missing = [v for v in self.nav_needed if self.info.get(v) is None]
        self.nav_seen = not missing
        if missing and now - self.start_time > self.nav_grace:
            self._warn_once(f"No {','.join(missing)} received after nav_grace={self.nav_grace:g} s")
        if self.hold_on_apps:
            clients = {c.strip() for c in str(self.info.get("DB_CLIENTS") or "").split(",")}
            absent = [a for a in self.hold_on_apps if a not in clients]
            if not absent:
                self.hold_on_apps = []
            elif now - self.start_time > self.nav_grace:
                self._warn_once(f"hold_on_apps: holding until {','.join(absent)} connect (DB_CLIENTS)")
        return bool(missing or self.hold_on_apps)

    # ---- one iteration ---------------------------------------------------------------
    def iterate(self, now: float) -> list[HelmPost]:
        self.iteration += 1
        if self.start_time is None:
            self.start_time = now
        out: list[HelmPost] = []
        if self.status != "DISABLED" or self.last_state != "DISABLED":
            out.append(("IVPHELM_STATE", self.status, ""))   # DISABLED is posted only on the change
        self.last_state = self.status
        if self.status not in ("PARK", "DRIVE"):
            return out
        if self._holding(now):
            return out
        if self.seen_own_state and not self.deferred_done:
            self.deferred_done = True
            for init in self.initializes:
                if init.deferred and self.info.get(init.var) is None:
                    self.info.set(init.var, init.value, now)
                    out.append((init.var, init.value, "HELM_VAR_INIT"))
        if self.status == "PARK":
            out += self._allstop("ManualOverride")
            return out
        if now - self.start_time < 1.0:
            return out
        loop_start = perf_counter()
        self._spawn(now, out)
        mode_posts = self._evaluate_modes(now)
        functions: list[IvPFunction] = []
        bhv_posts: list[tuple[str, list[Post]]] = []    # each behaviour's name and posts, in order
        for bhv in self.behaviors:
            fn = bhv.tick(now)
            if fn is not None:
                functions.append(fn)
            posts = bhv.take_posts()
            if posts:
                bhv_posts.append((bhv.name, posts))
        solve_start = perf_counter()
        self.decision = solve(self.domain, functions) if functions else {}
        self._note_time("create_time", solve_start - loop_start)
        self._note_time("solve_time", perf_counter() - solve_start)
        out += mode_posts
        error = False
        last_sent, info = self.last_sent, self.info
        for name, posts in bhv_posts:
            aux = f"{self.iteration}:{name}"
            for post in posts:
                var, value = post.var, post.value
                error = error or var == "BHV_ERROR"
                key = name + var + post.key
                if not post.repeatable and last_sent.get(key) == value:
                    continue
                last_sent[key] = value
                info.set(var, value, now)
                out.append((var, value, aux))
        out += self._life_events(now)
        missing = missing_decisions(self.domain, self.decision) if functions else []
        if error:
            status = "BehaviorError"
        elif not functions:
            status = "NothingToDo"
        elif missing:
            status = "MissingDecVars:" + ",".join(missing)
            out.append(("BHV_ERROR", status, ""))
        else:
            status = "clear"
        self._note_time("loop_time", perf_counter() - loop_start)
        out += self._summary(now, functions, halted=status == "BehaviorError")
        out += self._allstop(status)
        self.info.clear_deltas()
        return out

    def _note_time(self, name: str, seconds: float) -> None:
        self.timing[name] = seconds
        if seconds > self.timing["max_" + name]:
            self.timing["max_" + name] = seconds

    def _allstop(self, status: str) -> list[HelmPost]:
        out: list[HelmPost] = []
        if status != self.allstop_status:
            empty = status in EMPTY_DECISIONS or status.startswith("MissingDecVars")
            out.append(("IVPHELM_ALLSTOP", status, ""))
            if empty and self.allstop_status != "IncompleteOrEmptyDecision":
                self.allstop_status = "IncompleteOrEmptyDecision"
            else:
                self.allstop_status = status
                if status != "clear":
                    out += [(self._desired_name(v.name, prefixed=False), 0.0, "") for v in self.domain.vars]
        if status != "clear" and self.park_on_allstop and self.allow_park:
            self.status = "PARK"
        if status == "clear":
            out += [(self.desired_names[n], float(v), "") for n, v in self.decision.items()]
        return out

    def _desired_name(self, var: str, prefixed: bool = True) -> str:
        name = "DESIRED_HEADING" if var == "course" else f"DESIRED_{var.upper()}"
        return f"{self.helm_prefix}{name}" if prefixed else name   # plain concatenation, as MOOS-IvP

    # ---- modes ----------------------------------------------------------------------
    def _evaluate_modes(self, now: float) -> list[HelmPost]:
        if not self.modes:
            return []
        pushed: dict[str, Value] = {}

        def lookup(var: str) -> Value | None:
            return pushed[var] if var in pushed else self.info.get(var)

        for entry in self.modes:
            if all(c.evaluate(lookup) for c in entry.conditions):
                value = entry.value
            elif all(c.evaluate(lookup) for c in entry.mode_var_conditions):
                value = entry.else_value
            else:
                value = ""
            if value:
                pushed[entry.var] = f"{entry.prefix}:{value}" if entry.prefix else value
        out: list[HelmPost] = []
        for var in sorted(pushed):
            number = as_number(str(pushed[var]))
            value = number if number is not None else pushed[var]
            self.info.set(var, value, now)
            if self.mode_values.get(var) != value:
                self.mode_values[var] = value
                self._modes_text = None
                out.append((var, value, ""))
        return out

    # ---- behaviours ------------------------------------------------------------------
    def _spawn(self, now: float, out: list[HelmPost]) -> None:
        for name, (spec, template) in self.templates.items():
            for raw in self.info.deltas.get(template.updates_var, []):
                pairs = dict(p.strip().partition("=")[::2] for p in str(raw).split("#"))
                suffix = pairs.get("name", "").strip()
                full = name + suffix
                if not suffix or any(b.name == full for b in self.behaviors):
                    continue
                bhv = build_behavior(spec, self.domain, self.info, self.ownship)
                bhv.spawn_as(suffix)
                self.behaviors.append(bhv)
                out.append(("IVPHELM_LIFE_EVENT", f"iter={self.iteration},time={now:.2f},bname={full},"
                            f"btype={bhv.type_name},event=spawn,seed={raw}", ""))

    def _life_events(self, now: float) -> list[HelmPost]:
        out: list[HelmPost] = []
        for bhv in [b for b in self.behaviors if b.state == "completed"]:
            self.behaviors.remove(bhv)
            out.append(("IVPHELM_LIFE_EVENT", f"iter={self.iteration},time={now:.2f},bname={bhv.name},"
                        f"btype={bhv.type_name},event=death", ""))
        return out

    def _summary(self, now: float, functions: list[IvPFunction], halted: bool) -> list[HelmPost]:
        names, states = [b.name for b in self.behaviors], [b.state for b in self.behaviors]
        if names != self._grouped[0] or states != self._grouped[1]:    # the groups' texts, made when they change
            groups = {"ACTIVE": [], "RUNNING": [], "IDLE": [], "COMPLETED": []}
            for name, state in zip(names, states):
                groups.get(state.upper(), groups["IDLE"]).append(name)
            self._grouped = (names, states, {kind: (",".join(g), ":".join(g) or "none", float(len(g)))
                                                   for kind, g in groups.items()})
        texts = self._grouped[2]
        if self._modes_text is None:
            self._modes_text = "#".join(f"{k}@{v}" for k, v in sorted(self.mode_values.items()))
        timing = self.timing
        values = [str(len(functions)), str(len(self.config_warnings) + len(self.run_warnings)),
                  *["%.4f" % timing[k] for k in TIMING_FIELDS],    # printf-style: cheaper than format specs
                  "true" if halted else "false",   # a behaviour posted BHV_ERROR
                  "false", self._modes_text, texts["ACTIVE"][1], texts["RUNNING"][1], texts["IDLE"][1],
                  texts["COMPLETED"][1]]
        for v in self.domain.vars:
            d = self.decision.get(v.name)
            values.append("%s:%g" % (v.name, d) if d is not None else f"{v.name}:varbalk")
        last = self.summary_values
        fields = [f"iter={self.iteration}", "utc_time=%.2f" % _time.time()]
        if len(last) != len(values):
            last = [None] * len(values)
        for i, value in enumerate(values):      # the fields that changed since the last summary
            if value != last[i]:
                fields.append(f"{SUMMARY_KEYS[i]}={value}" if i < len(SUMMARY_KEYS) else f"var={value}")
        self.summary_values = values
        out: list[HelmPost] = [("IVPHELM_ITER", float(self.iteration), ""), ("IVPHELM_SUMMARY", ",".join(fields), "")]
        for kind in ("ACTIVE", "RUNNING", "IDLE"):
            text = texts[kind][0]
            if self.bhv_lists.get(kind) != text:
                self.bhv_lists[kind] = text
                out += [(f"IVPHELM_BHV_{kind}", text, ""), (f"IVPHELM_BHV_{kind}_CNT", texts[kind][2], "")]
        return out
