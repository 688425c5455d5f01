"""pHelmIvP: the MOOS shell around the helm engine (behaviors.helm.Helm)."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from moosdb_py.app import MOOSApp
from moosdb_py.formats import FormatError, parse_pairs
from moosdb_py.geodesy import mission_grid
from moosdb_py.source import MissionFileError

from .bhv_file import BhvFile, read_bhv
from .domain import IvPDomain, parse_domain_line
from .helm import Helm
from .logic import as_number
from .parameters import parse_bool

EXEMPT_FROM_SKEW = ("HELM_MAP_CLEAR",)
# Every key the pHelmIvP block may hold (docs/spec/mission-files.md §1.5), the MOOSApp base's own included;
# anything else is a config warning that puts the helm in MALCONFIG, as the C++ helm does.
KNOWN_PARAMS = frozenset({
    "apptick", "commstick", "maxappticks", "maxapptick", "iteratemode", "debug", "app_logging",
    "behaviors", "domain", "active_start", "start_engaged", "start_in_drive", "allow_park", "park_on_allstop",
    "helm_prefix", "ok_skew", "goals_mandatory", "nav_grace", "hold_on_apps", "verbose",
    "bhv_dir_not_found_ok", "ivp_behavior_dir", "ivp_behavior_dirs", "pmgen"})
NOT_SUPPORTED = frozenset({"standby", "other_override_var"})   # real pHelmIvP keys this helm lacks
# Keys the C++ helm does not read but only warns about (the mission runs): warned here too.
WARNED_ONLY = frozenset({"term_report_interval"})


def parameter_warnings(config) -> list[MissionFileError]:
    """Each line of a pHelmIvP block that puts the helm in MALCONFIG (str: `file:line: message`)."""
    out = []
    for entry in config.entries:
        if entry.key.lower() in NOT_SUPPORTED:
            out.append(entry.source.error(f"pHelmIvP parameter '{entry.key}' is not supported by this helm"))
        elif entry.key.lower() == "pmgen" and not _key_value_list(entry.value):
            out.append(entry.source.error(f"pmgen must be a key=value list (platform model parameters), "
                                          f"got '{entry.value}'"))
        elif entry.key.lower() not in KNOWN_PARAMS | WARNED_ONLY:
            out.append(entry.source.error(f"unknown pHelmIvP parameter '{entry.key}'"))
    return out


def ignored_parameter_warnings(config) -> list[MissionFileError]:
    """Lines of a pHelmIvP block the helm ignores with a warning, as the C++ helm does (it still drives)."""
    return [entry.source.error(f"pHelmIvP ignores '{entry.key}' (the C++ helm only warns about it)")
            for entry in config.entries if entry.key.lower() in WARNED_ONLY]


def _key_value_list(text: str) -> bool:
    try:
        parse_pairs(text)
    except FormatError:
        return False
    return True


class HelmIvP(MOOSApp):
    """pHelmIvP: the IvP helm. Reads the .bhv files named by `behaviors =`, evaluates the mode set
    and behaviour conditions every iteration, solves the behaviours' objective functions over the
    decision domain and posts DESIRED_HEADING / DESIRED_SPEED (and DESIRED_DEPTH) while in DRIVE.
    It starts in PARK; MOOS_MANUAL_OVERRIDE=false puts it in DRIVE (unless active_start = true).
    An unknown behaviour type, a bad behaviour parameter or a broken .bhv file is a start-up error
    naming file:line."""

    default_name = "pHelmIvP"
    example_config = """\
ProcessConfig = pHelmIvP
{
  AppTick    = 4                  // helm iterations per (warped) second
  CommsTick  = 4

  behaviors  = alpha.bhv          // repeatable; read in sorted file-name order
  domain     = course:0:359:360   // name:low:high:npts[:optional] or name:low:high:delta=D
  domain     = speed:0:4:41

  active_start    = false         // true (aliases start_engaged, start_in_drive): DRIVE at start
  allow_park      = true          // MOOS_MANUAL_OVERRIDE=true may park the helm
  park_on_allstop = false         // any all-stop other than clear parks the helm
  helm_prefix     =               // prepended to the DESIRED_* names (e.g. SIM_ -> SIM_DESIRED_HEADING)
  ok_skew         = 60            // seconds, or any: ignore mail stamped further from MOOS time
  goals_mandatory = false         // accepted for compatibility
  nav_grace       = 5             // seconds without NAV_* before a warning (counted in IVPHELM_SUMMARY)
  hold_on_apps    =               // comma list: make no decision until these apps are in DB_CLIENTS
  verbose         = false         // accepted for compatibility
  bhv_dir_not_found_ok = false    // accepted for compatibility (no behaviour libraries to load)
  app_logging     = false         // accepted for compatibility
  pmgen           =               // platform-model parameters (key=value list): checked, accepted
}
// Any other parameter puts the helm in MALCONFIG (it never drives) with a file:line warning;
// term_report_interval is only warned about, as the C++ helm does."""
    interface = """\
SUBSCRIPTIONS
  NAV_X, NAV_Y, NAV_HEADING, NAV_SPEED, NAV_DEPTH     ownship navigation
  MOOS_MANUAL_OVERRIDE (and MOOS_MANUAL_OVERIDE)      "false" = drive, "true" = park
  HELM_MAP_CLEAR                                      re-post everything (viewers)
  DB_CLIENTS                                          for hold_on_apps
  IVPHELM_STATE                                       another helm posting disables this one
  NODE_REPORT                                         other vehicles, when a contact behaviour is configured
  every variable in behaviour/mode/flag conditions, updates and duration_reset variables
PUBLICATIONS
  DESIRED_HEADING, DESIRED_SPEED, DESIRED_<VAR>       the decision (double), every iteration
  IVPHELM_STATE      PARK | DRIVE | MALCONFIG | DISABLED, every iteration
  IVPHELM_ALLSTOP    clear | NothingToDo | MissingDecVars:.. | BehaviorError | ManualOverride
  IVPHELM_SUMMARY, IVPHELM_ITER, IVPHELM_BHV_ACTIVE/RUNNING/IDLE[_CNT], IVPHELM_LIFE_EVENT
  IVPHELM_UPDATE_RESULT, IVPHELM_DOMAIN, IVPHELM_MODESET, IVPHELM_STATEVARS, IVPHELM_REGISTER,
  PLOGGER_CMD, PHELMIVP_PID, BHV_STATUS
  NODE_MESSAGE_LOCAL  flags written `#all VAR = value` etc., for uFldNodeBroker to send on
  mode variables (e.g. MODE = ACTIVE:SURVEYING), initialize values, behaviour flags and posts
  (WPT_STAT, WPT_INDEX, CYCLE_INDEX, VIEW_POINT, VIEW_SEGLIST, VIEW_POLYGON, DIST_TO_STATION,
  PSKEEP_MODE, BHV_WARNING, BHV_ERROR, BHV_SETTINGS, OPREG_*, RANGE_AVD_<CONTACT>,
  CLSG_SPD_AVD_<CONTACT>, ...)
  BCM_ALERT_REQUEST  at start-up, from each spawning BHV_AvoidCollision template"""

    def on_startup(self) -> None:
        cfg = self.config
        names = cfg.get_all("behaviors")
        if not names:
            raise ValueError("behaviors: no .bhv file given (behaviors = file.bhv)")
        if len(set(names)) != len(names):
            raise ValueError(f"behaviors: a file is named twice: {', '.join(names)}")
        files: list[BhvFile] = [read_bhv(self._find(n)) for n in sorted(names)]
        lines = cfg.get_all("domain")
        if not lines:
            raise ValueError("domain: no decision domain given (domain = course:0:359:360)")
        domain = IvPDomain(vars=[self._domain_var(text) for text in lines])
        active = any(parse_bool(cfg.get(k), k) for k in ("active_start", "start_engaged", "start_in_drive")
                     if cfg.get(k) is not None)
        skew = (cfg.get("ok_skew", "60") or "60").strip().lower()
        if skew != "any" and (as_number(skew) is None or as_number(skew) < 0):
            raise ValueError(f"ok_skew must be seconds or 'any', got '{skew}'")
        self.ok_skew = None if skew == "any" else as_number(skew)
        ownship = self.mission.community if self.mission is not None else self.name
        self.helm = Helm(files, domain, ownship, app_name=self.name, active_start=active,
                         allow_park=parse_bool(cfg.get("allow_park", "true"), "allow_park"),
                         park_on_allstop=parse_bool(cfg.get("park_on_allstop", "false"), "park_on_allstop"),
                         helm_prefix=cfg.get("helm_prefix", "") or "")
        parse_bool(cfg.get("goals_mandatory", "false"), "goals_mandatory")   # checked; goal behaviours do not exist here
        grace = as_number(cfg.get("nav_grace", "5") or "")
        if grace is None or grace < 0:
            raise ValueError(f"nav_grace must be seconds >= 0, got '{cfg.get('nav_grace')}'")
        self.helm.nav_grace = grace
        self.helm.hold_on_apps = [a.strip() for v in cfg.get_all("hold_on_apps") for a in v.split(",") if a.strip()]
        for warning in parameter_warnings(self.config):
            self.helm.malconfig(str(warning))
        for warning in ignored_parameter_warnings(self.config):
            print(f"{self.name}: warning: {warning}", file=sys.stderr)
        if self.mission is not None and (self.mission.lat_origin is None or self.mission.long_origin is None):
            self.helm.malconfig(f"{self.mission.path}: LatOrigin/LongOrigin not set")
        else:
            self.helm.grid = mission_grid(self.mission)
        for warning in self.helm.config_warnings:
            print(f"{self.name}: {warning} -> MALCONFIG, the helm will not drive", file=sys.stderr)
        self.warned = len(self.helm.run_warnings)
        self.bhv_paths = [f.path for f in files]
        self.pending_startup = self.helm.startup(self.moos_time())
        self.registered_at: dict[str, float] = {}

    def _find(self, name: str) -> Path:
        """A .bhv file relative to the working directory (as pHelmIvP), else to the mission's folder."""
        path = Path(name)
        if not path.is_file() and self.mission is not None and not path.is_absolute():
            beside = Path(self.mission.path).parent / name
            if beside.is_file():
                return beside
        if not path.is_file():
            raise ValueError(f"behaviors: file '{name}' not found (from {os.getcwd()})")
        return path

    @staticmethod
    def _domain_var(text: str):
        try:
            return parse_domain_line(text)
        except ValueError as exc:
            raise ValueError(f"domain: {exc}") from None

    def on_connect(self) -> None:
        now = self.moos_time()
        for var in self.helm.subscriptions():
            self.register(var)
            self.registered_at.setdefault(var, now)
        if self.pending_startup:
            for var, value, aux in self.pending_startup:
                self.notify(var, value, source_aux=aux)
            for path in self.bhv_paths:
                self.notify("PLOGGER_CMD", f"COPY_FILE_REQUEST = {path}")
            self.notify("PHELMIVP_PID", float(os.getpid()))
            self.pending_startup = []

    def on_new_mail(self, mail) -> None:
        now = self.moos_time()
        for msg in mail:
            if self._skewed(msg, now):
                self.notify("IVPHELM_SKEW", f"var={msg.key},skew={abs(now - msg.time):.1f},src={msg.source}")
                continue
            self.helm.on_mail(msg.key, msg.value, msg.time, msg.source)

    def _skewed(self, msg, now: float) -> bool:
        if self.ok_skew is None or msg.key in EXEMPT_FROM_SKEW or msg.source == self.name:
            return False
        since_registration = now - self.registered_at.get(msg.key, now)
        return min(abs(now - msg.time), since_registration) > self.ok_skew

    def iterate(self) -> None:
        for var, value, aux in self.helm.iterate(self.moos_time()):
            self.notify(var, value, source_aux=aux)
        for warning in self.helm.run_warnings[self.warned:]:
            print(f"{self.name}: {warning}", file=sys.stderr)
        self.warned = len(self.helm.run_warnings)

    def status_fields(self) -> dict:
        return {"state": self.helm.status, "iter": self.helm.iteration,
                "warnings": len(self.helm.config_warnings) + len(self.helm.run_warnings)}


main = HelmIvP.main
