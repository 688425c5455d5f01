"""uTimerScript: posts a script of variable assignments at set (or random) times, MOOS-IvP style.

Missions use it to inject events (moving a loiter centre, a fault, a deploy) on a schedule that
follows the mission clock, so it honours MOOSTimeWarp and its own `time_warp`, can be paused,
fast-forwarded and reset from the DB, and can wait on logic conditions. It lives in `behaviors`
because those conditions are the helm's logic-condition language.

The script itself is `TimerScriptState` (moos-time steps and mail in, posts out); the MOOSApp only
moves mail and posts.
"""
from __future__ import annotations

import logging
import random
import re
from dataclasses import dataclass, field

from behaviors.logic import ConditionError, as_number, condition_variables, parse_condition
from moosdb_py.app import MOOSApp
from moosdb_py.formats import FormatError, parse_bool, parse_pairs
from moosdb_py.message import MOOSMsg

log = logging.getLogger("uTimerScript")

Post = tuple[str, str | float]
RANDVAR_KEYS = ("at_start", "at_reset", "at_post")
RESET_AT_END = ("all-posted", "end")


def fields_of(text: str, where: str) -> dict[str, str]:
    """A `key=value` line whose quoted values keep their commas (and their quotes: `val="x"` is a string)."""
    try:
        return parse_pairs(text)
    except FormatError as exc:
        raise ValueError(f"{where}: {exc}") from None


def parse_range(text: str, where: str) -> tuple[float, float]:
    """`T` or `T1:T2` (a uniform random pick in [T1, T2]); negative or reversed is an error."""
    lo_text, _, hi_text = text.partition(":")
    lo, hi = as_number(lo_text), as_number(hi_text or lo_text)
    if lo is None or hi is None or lo < 0 or hi < lo:
        raise ValueError(f"{where}: {text!r} is not a time T or a range T1:T2 with 0 <= T1 <= T2")
    return lo, hi


@dataclass
class Event:
    var: str
    val: str
    quoted: bool                  # a quoted value is always posted as a string
    window: tuple[float, float]
    time: float = 0.0             # this round's pick from the window
    posted: bool = False

    @classmethod
    def parse(cls, text: str, where: str) -> "Event":
        pairs = fields_of(text, where)
        unknown = set(pairs) - {"var", "val", "time"}
        if unknown or not pairs.get("var") or "val" not in pairs:
            raise ValueError(f"{where}: event '{text}' is not var=NAME, val=VALUE, time=T[:T2]")
        val = pairs["val"]
        quoted = len(val) >= 2 and val[0] == val[-1] == '"'
        return cls(pairs["var"], val[1:-1] if quoted else val, quoted,
                   parse_range(pairs.get("time", "0"), f"{where}: time"))


@dataclass
class RandVar:
    """`randvar = varname=X, min=a, max=b, key=at_reset`: the `$[X]` macro."""

    name: str
    lo: float
    hi: float
    key: str
    value: float = 0.0

    @classmethod
    def parse(cls, text: str, where: str) -> "RandVar":
        pairs = fields_of(text, where)
        lo, hi = as_number(pairs.get("min", "")), as_number(pairs.get("max", ""))
        key = pairs.get("key", "at_start").lower()
        if not pairs.get("varname") or lo is None or hi is None or hi < lo or key not in RANDVAR_KEYS:
            raise ValueError(f"{where}: randvar '{text}' is not varname=X, min=a, max=b[, key=at_start|at_reset|at_post]")
        return cls(pairs["varname"], lo, hi, key)


def format_value(value: float) -> str:
    text = f"{value:.3f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


@dataclass
class TimerScriptState:
    """The script clock and its events. Times are script seconds: MOOS seconds times `time_warp`."""

    events: list[Event]
    script_name: str = "unnamed"
    paused: bool = False
    reset_max: int | None = None        # None: unlimited
    reset_time: str = "none"            # none, all-posted (end), or script seconds
    delay_start: tuple[float, float] = (0.0, 0.0)
    delay_reset: tuple[float, float] = (0.0, 0.0)
    time_warp: tuple[float, float] = (1.0, 1.0)
    conditions: list = field(default_factory=list)
    upon_awake: str = "none"            # none, reset/restart: a script whose conditions turn true starts over
    randvars: list[RandVar] = field(default_factory=list)
    rng: random.Random = field(default_factory=random.Random)
    elapsed: float = 0.0
    delay_left: float = 0.0
    warp: float = 1.0
    resets: int = 0
    count: int = 0                      # posts since the last reset
    total: int = 0                      # posts ever
    conditions_ok: bool = True
    values: dict[str, float | str] = field(default_factory=dict)   # latest mail for the conditions

    def __post_init__(self) -> None:
        for var in self.randvars:
            var.value = self.rng.uniform(var.lo, var.hi)
        self._new_round(self.delay_start)

    def _new_round(self, delay: tuple[float, float]) -> None:
        self.elapsed, self.count = 0.0, 0
        self.delay_left = self.rng.uniform(*delay)
        self.warp = self.rng.uniform(*self.time_warp)
        for event in self.events:
            event.time, event.posted = self.rng.uniform(*event.window), False
        for var in self.randvars:
            if var.key == "at_reset":
                var.value = self.rng.uniform(var.lo, var.hi)

    def reset(self) -> bool:
        """Start the script over (after `delay_reset`), unless `reset_max` resets are used up."""
        if self.reset_max is not None and self.resets >= self.reset_max:
            return False
        self.resets += 1
        self._new_round(self.delay_reset)
        return True

    def forward(self, value: float | str) -> None:
        """FORWARD mail: N > 0 skips N script seconds; anything else jumps to the next event."""
        number = value if isinstance(value, float) else as_number(str(value))
        if number is not None and number > 0:
            self.elapsed += number
        else:
            pending = [e.time for e in self.events if not e.posted]
            self.elapsed = max(self.elapsed, min(pending, default=self.elapsed))
        self.delay_left = 0.0

    def pause(self, value: str) -> None:
        word = str(value).strip().lower()
        self.paused = (not self.paused) if word == "toggle" else parse_bool(word)

    def on_mail(self, key: str, value: float | str) -> None:
        self.values[key] = value
        ok = all(c.evaluate(self.values.get) for c in self.conditions)
        if ok and not self.conditions_ok and self.upon_awake in ("reset", "restart"):
            self.reset()
        self.conditions_ok = ok

    def step(self, dt: float, macros: dict[str, str]) -> list[Post]:
        """Advance by `dt` MOOS seconds and return the posts now due, in time order."""
        if self.paused or not self.conditions_ok:
            return []
        dt *= self.warp
        used = min(dt, self.delay_left)
        self.delay_left -= used
        self.elapsed += dt - used
        posts: list[Post] = []
        for event in sorted((e for e in self.events if not e.posted and e.time <= self.elapsed), key=lambda e: e.time):
            event.posted = True
            self.count += 1
            self.total += 1
            posts.append((event.var, self.expand(event, macros)))
        if self._round_over():
            self.reset()
        return posts

    def _round_over(self) -> bool:
        if self.reset_time.lower() in RESET_AT_END:
            return bool(self.events) and all(e.posted for e in self.events)
        number = as_number(self.reset_time)
        return number is not None and self.elapsed >= number

    def expand(self, event: Event, macros: dict[str, str]) -> str | float:
        for var in self.randvars:
            if var.key == "at_post":
                var.value = self.rng.uniform(var.lo, var.hi)
        table = {**macros, "COUNT": str(self.count), "TCOUNT": str(self.total)}
        text = re.sub(r"\$\((\w+)\)", lambda m: table.get(m.group(1), m.group(0)), event.val)
        randoms = {v.name: format_value(v.value) for v in self.randvars}
        text = re.sub(r"\$\[(\w+)\]", lambda m: randoms.get(m.group(1), m.group(0)), text)
        number = None if event.quoted else as_number(text)
        return text if number is None else number

    def status(self) -> str:
        posted = sum(e.posted for e in self.events)
        return (f"name={self.script_name},elapsed_time={self.elapsed:.2f},posted={posted},"
                f"pending={len(self.events) - posted},paused={str(self.paused).lower()},"
                f"conditions_ok={str(self.conditions_ok).lower()},time_warp={format_value(self.warp)},"
                f"start_delay={format_value(self.delay_left)},upon_awake={self.upon_awake},"
                f"resets={self.resets}/{'any' if self.reset_max is None else self.reset_max}")


class TimerScript(MOOSApp):
    """uTimerScript: posts `event` lines (var, val, time) on the script clock.

    Times may be ranges (`time=10:20`, picked at random every round). The script clock runs at the
    mission's MOOSTimeWarp times its own `time_warp`, only while not paused and while every
    `condition` holds. A round ends per `reset_time` and the script starts over, at most
    `reset_max` times. Values may hold $(DBTIME), $(UTCTIME), $(COUNT), $(TCOUNT) and the
    `randvar` macros $[NAME]; an unquoted numeric value is posted as a double.
    """

    default_name = "uTimerScript"
    example_config = """\
ProcessConfig = uTimerScript
{
  AppTick   = 4
  CommsTick = 4

  event = var=DEPLOY, val=true, time=10              // repeatable; time=T or T1:T2 (random)
  event = var=UP_LOITER, val="center_assign=$[X],-50", time=60:90

  randvar = varname=X, min=0, max=50, key=at_reset   // $[X]; key at_start|at_reset|at_post (default at_start)

  paused      = false        // start paused (default false)
  reset_max   = unlimited    // resets allowed, a number or unlimited (default unlimited)
  reset_time  = none         // none, all-posted (or end), or script seconds (default none)
  delay_start = 0            // script seconds before the first round, T or T1:T2 (default 0)
  delay_reset = 0            // script seconds before each later round, T or T1:T2 (default 0)
  time_warp   = 1            // the script's own warp on top of MOOSTimeWarp, T or T1:T2 (default 1)
  condition   = MODE = SURVEY   // repeatable; the clock runs only while all hold (default none)
  upon_awake  = none         // none, or reset/restart: start over when the conditions turn true
  script_name = unnamed      // shown in the status (default unnamed)

  forward_var = UTS_FORWARD  // N > 0: skip N seconds; 0: jump to the next event (default UTS_FORWARD)
  pause_var   = UTS_PAUSE    // true, false or toggle (default UTS_PAUSE)
  reset_var   = UTS_RESET    // any post starts the script over (default UTS_RESET)
  status_var  = UTS_STATUS   // where the status goes, on every change (default UTS_STATUS)
  verbose     = false        // print every post on the terminal (default false)
}
"""
    interface = """\
SUBSCRIPTIONS:
  UTS_FORWARD (forward_var)  N > 0: fast-forward N script seconds; 0: to the next event
  UTS_PAUSE   (pause_var)    true / false / toggle
  UTS_RESET   (reset_var)    any value: start the script over
  DB_UPTIME                  for the $(DBTIME) macro
  every variable named in a condition

PUBLICATIONS:
  every event's var, at its time
  UTS_STATUS (status_var)    name=unnamed,elapsed_time=12.50,posted=1,pending=3,paused=false,
                             conditions_ok=true,time_warp=1,start_delay=0,upon_awake=none,resets=0/any
"""

    def on_startup(self) -> None:
        cfg = self.config
        events = [Event.parse(value, where) for value, where in self._lines("event")]
        randvars = [RandVar.parse(value, where) for value, where in self._lines("randvar")]
        conditions = []
        for value, where in self._lines("condition"):
            try:
                conditions.append(parse_condition(value))
            except ConditionError as exc:
                raise ValueError(f"{where}: {exc}") from None
        reset_max_text = self._setting("reset_max", "unlimited").lower()
        if reset_max_text not in ("unlimited", "any") and not reset_max_text.isdigit():
            raise ValueError(f"{self._where('reset_max')}: {reset_max_text!r} is not a count or unlimited")
        reset_time = self._setting("reset_time", "none")
        if reset_time.lower() not in ("none", *RESET_AT_END) and as_number(reset_time) is None:
            raise ValueError(f"{self._where('reset_time')}: {reset_time!r} is not none, all-posted, end or seconds")
        upon_awake = self._setting("upon_awake", "none").lower()
        if upon_awake not in ("none", "reset", "restart"):
            raise ValueError(f"{self._where('upon_awake')}: {upon_awake!r} is not none, reset or restart")
        self.state = TimerScriptState(
            events, script_name=self._setting("script_name", "unnamed"),
            paused=parse_bool(self._setting("paused", "false")),
            reset_max=None if reset_max_text in ("unlimited", "any") else int(reset_max_text), reset_time=reset_time,
            delay_start=parse_range(self._setting("delay_start", "0"), self._where("delay_start")),
            delay_reset=parse_range(self._setting("delay_reset", "0"), self._where("delay_reset")),
            time_warp=parse_range(self._setting("time_warp", "1"), self._where("time_warp")),
            conditions=conditions, upon_awake=upon_awake, randvars=randvars)
        self.state.conditions_ok = not conditions
        self.forward_var = self._setting("forward_var", "UTS_FORWARD")
        self.pause_var = self._setting("pause_var", "UTS_PAUSE")
        self.reset_var = self._setting("reset_var", "UTS_RESET")
        self.status_var = self._setting("status_var", "UTS_STATUS")
        self.verbose = parse_bool(self._setting("verbose", "false"))
        self.condition_vars = condition_variables(conditions)
        self.last_step: float | None = None
        self.last_status = ""
        self.db_uptime: tuple[float, float] | None = None    # (DB_UPTIME, our time when it came)

    def _lines(self, key: str) -> list[tuple[str, str]]:
        """Every value of a repeatable parameter, with its `file:line: key` for messages."""
        return [(e.value, f"{e.source}: {key}") for e in self.config.entries if e.key.lower() == key]

    def _setting(self, key: str, default: str) -> str:
        return (self.config.get(key) or default).strip()

    def _where(self, key: str) -> str:
        entry = self.config.entry(key)
        return f"{entry.source}: {key}" if entry is not None else f"{self.name}: {key}"

    def on_connect(self) -> None:
        for var in (self.forward_var, self.pause_var, self.reset_var, "DB_UPTIME", *self.condition_vars):
            self.register(var)

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        for msg in mail:
            if msg.key == "DB_UPTIME" and msg.is_double():
                self.db_uptime = (msg.double, self.moos_time())
            if msg.key == self.forward_var:
                self.state.forward(msg.value)
            elif msg.key == self.pause_var:
                try:
                    self.state.pause(str(msg.value))
                except FormatError as err:  # a bad poke is refused; the script keeps its state
                    log.warning("%s from %s ignored: %s", self.pause_var, msg.sender, err)
            elif msg.key == self.reset_var:
                self.state.reset()
            if msg.key in self.condition_vars and not msg.is_binary():
                self.state.on_mail(msg.key, msg.value)

    def macros(self, now: float) -> dict[str, str]:
        db_time = now - self.start_time if self.db_uptime is None else self.db_uptime[0] + now - self.db_uptime[1]
        return {"DBTIME": f"{db_time:.2f}", "UTCTIME": f"{now:.2f}"}

    def iterate(self) -> None:
        now = self.moos_time()
        dt = 0.0 if self.last_step is None else now - self.last_step
        self.last_step = now
        for key, value in self.state.step(dt, self.macros(now)):
            self.notify(key, value)
            if self.verbose:
                print(f"{self.name}: {key} = {value} (script time {self.state.elapsed:.2f})", flush=True)
        status = self.state.status()
        if status.split(",", 2)[2] != self.last_status:   # elapsed_time alone is no change
            self.last_status = status.split(",", 2)[2]
            self.notify(self.status_var, status)

    def status_fields(self) -> dict:
        return {"script_name": self.state.script_name, "resets": self.state.resets}


main = TimerScript.main
