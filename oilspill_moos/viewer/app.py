"""pMarineViewer: the live operations map, served to a browser; also replays a pLogger .alog."""
from __future__ import annotations

import asyncio
import bisect
import contextlib
import logging
import signal
import subprocess
import sys
from pathlib import Path

from moosdb_py.alog import AlogFormatError, iter_alog
from moosdb_py.app import MOOSApp
from moosdb_py.config import config_float, config_str, read_params, warn_unhandled
from moosdb_py.mission import read_mission
from moosdb_py.source import MissionFileError
from oilspill_moos.forecaster.push import DEFAULT_PORT as BOUNDARY_PORT, BoundaryPusher, PushRejected, PushUnreachable
from moosdb_py.geodesy import LocalGrid, mission_grid
from oilspill_moos.viewer.model import (
    REPORT_KEYS,
    SUBSCRIPTIONS,
    VIEW_KINDS,
    WILDCARDS,
    Button,
    Scene,
    ViewError,
    merge_button,
    parse_action,
    parse_button,
)
from oilspill_moos.viewer.server import MapServer

log = logging.getLogger("oilspill_moos.viewer")

BUTTON_KEYS = ("button_one", "button_two", "button_three", "button_four", "button_five", "button_six",
               "button_seven", "button_eight", "button_nine", "button_ten")
DEFAULT_BUTTON = "DEPLOY # DEPLOY_ALL=true # MOOS_MANUAL_OVERRIDE_ALL=false # RETURN_ALL=false"
RETURN_BUTTON = "RETURN_ALL # RETURN_ALL=true"
KNOWN = {"http_host", "http_port", "refresh_hz", "trail_length", "boundary_host", "boundary_port", "action",
         *BUTTON_KEYS}
# Parameters of the C++ pMarineViewer that this viewer does not implement (display layout, fonts,
# background image, pop-up commands, ...): missions written for it carry them, so they are summed up
# in one line instead of a warning each; an unknown key is still warned about by itself.
CPP_VIEWER_KEYS = frozenset({
    "action+", "app_logging", "appcast_color_scheme", "appcast_font_size", "appcast_height",
    "appcast_viewable", "appcast_width", "beat_flag", "circle_viewable_all", "cmd",
    "comms_pulse_viewable_all", "content_mode", "datum_viewable", "drop_point_vertex_size",
    "drop_point_viewable_all", "full_screen", "grid_viewable_all", "hash_delta", "hash_shade", "hash_view",
    "hash_viewable", "infocast_viewable", "left_context", "log_the_image", "marker_viewable_all",
    "node_pulse_viewable_all", "nodes_font_size", "point_vertex_size", "point_viewable_all",
    "point_viewable_labels", "polygon_viewable_all", "polygon_viewable_labels", "procs_font_size",
    "realmcast_channel", "right_context", "scope", "seglist_edge_width", "seglist_vertex_color",
    "seglist_vertex_size", "seglist_viewable_all", "set_pan_x", "set_pan_y", "stale_remove_thresh",
    "stale_report_thresh", "tiff_file", "trails_color", "trails_length", "trails_point_size",
    "trails_viewable", "vehicle_shape_scale", "vehicles_active_color", "vehicles_inactive_color",
    "vehicles_name_mode", "vehicles_name_viewable", "vehicles_shape_scale", "vehicles_viewable",
    "watch_cluster", "zoom"})


def read_settings(config, mission) -> dict:
    """The viewer's ProcessConfig; `boundary_port` defaults to pPathAssign's in the same mission file."""
    path_assign = mission.process_config("pPathAssign") if mission is not None else None
    assigned_port = path_assign.get("boundary_port") if path_assign is not None else None
    buttons = []
    for key in BUTTON_KEYS:
        entries = [e for e in getattr(config, "entries", []) if e.key.lower() == key]
        lines = []
        for entry in entries:
            try:
                lines.append(parse_button(entry.value))
            except ViewError as exc:
                raise entry.source.error(str(exc)) from None
        if lines:
            try:
                buttons.append(merge_button(lines))
            except ViewError as exc:
                raise entries[0].source.error(str(exc)) from None
    actions = []
    for entry in (e for e in getattr(config, "entries", []) if e.key.lower() == "action"):
        try:
            actions.append(parse_action(entry.value))
        except ViewError as exc:
            raise entry.source.error(str(exc)) from None
    return {"http_host": config_str(config, "http_host", "127.0.0.1"),
            "http_port": int(config_float(config, "http_port", 8080, lo=0, hi=65535)),
            "refresh_hz": config_float(config, "refresh_hz", 10.0, lo=0.5, hi=60.0),
            "trail_length": int(config_float(config, "trail_length", 200, lo=0, hi=100000)),
            "boundary_host": config_str(config, "boundary_host", "127.0.0.1"),
            "boundary_port": int(config_float(config, "boundary_port", float(assigned_port or BOUNDARY_PORT),
                                              lo=1, hi=65535)),
            "buttons": (buttons or [parse_button(DEFAULT_BUTTON)]) + [parse_button(RETURN_BUTTON)],
            "actions": actions}


def ignored_cpp_keys(config) -> list[str]:
    """The block's C++ pMarineViewer parameters this viewer ignores, once each in order of appearance
    (a `left_context[station]` key is known by its `left_context` part)."""
    keys = [entry.key.lower() for entry in getattr(config, "entries", [])]
    return list(dict.fromkeys(k for k in keys if k.split("[", 1)[0] in CPP_VIEWER_KEYS and k not in KNOWN))


def warn_config(config, name: str) -> None:
    """One summary line for the C++ viewer's parameters, a warning each for keys nobody knows."""
    ignored = ignored_cpp_keys(config)
    if ignored:
        log.warning("%s: ignoring %d parameters of the C++ viewer it does not implement: %s",
                    name, len(ignored), ", ".join(ignored))
    warn_unhandled(config, KNOWN | set(ignored))


def runs_a_spill(mission, config) -> bool:
    """An oil-spill mission: its file runs pPathAssign (or the viewer is told where its boundary
    server is). Otherwise (s1_alpha, ...) the page shows no spill key and no RE-PUSH BOUNDARY."""
    if config is not None and config.get("boundary_port") is not None:
        return True
    return mission is not None and mission.process_config("pPathAssign") is not None


def page_setup(grid: LocalGrid | None, buttons: list[Button], community: str, mode: str, t0: float = 0.0,
               actions: list[Button] = (), spill: bool = True) -> dict:
    """What the page needs besides the picture: buttons, the time its mission clock counts from (`t0`),
    whether it is an oil-spill mission (`spill`), and a linear lat/long readout and grid about the
    origin (derivatives from pyproj over +-1 km: metre-accurate within a few km, which is where a
    spill is)."""
    origin = None
    if grid is not None:
        lat0, lon0 = (float(v) for v in grid.to_latlon(0.0, 0.0))
        lat_e, lon_e = (float(v) for v in grid.to_latlon(1000.0, 0.0))
        lat_n, lon_n = (float(v) for v in grid.to_latlon(0.0, 1000.0))
        origin = {"lat": lat0, "lon": lon0, "dlat_dx": (lat_e - lat0) / 1000, "dlon_dx": (lon_e - lon0) / 1000,
                  "dlat_dy": (lat_n - lat0) / 1000, "dlon_dy": (lon_n - lon0) / 1000}
    return {"mode": mode, "community": community, "origin": origin, "t0": t0, "spill": spill,
            "buttons": [b.label for b in buttons] + (["RE-PUSH BOUNDARY"] if mode == "live" and spill else []),
            "actions": [a.label for a in actions]}


class MarineViewer(MOOSApp):
    """pMarineViewer: a web operations map of the shoreside community. Vehicles (NODE_REPORT) with
    heading and trails, the spill boundary in force, the forecast boundaries per horizon with their
    uncertainty bands, each vehicle's start point and containment loop, the vessels' oil
    observations, VIEW_POLYGON / VIEW_SEGLIST / VIEW_POINT markers, the phase of every vehicle and
    the pPathAssign status line, served on http://127.0.0.1:<http_port>/ and pushed over a WebSocket.
    Buttons poke the MOOSDB (stamped with the community's warped time), RETURN_ALL recalls the
    fleet and RE-PUSH BOUNDARY sends the boundary in force to pPathAssign again.

    Extra options:
      --http_port=N     the page's port (overrides http_port; 0 picks a free one)
      --replay=FILE     play a pLogger .alog back on the same page (time slider, speed); no MOOSDB
    """

    default_name = "pMarineViewer"
    http_port_option: int | None = None
    example_config = """\
ProcessConfig = pMarineViewer
{
  AppTick   = 4
  CommsTick = 4

  http_host     = 127.0.0.1   // where the page is served (loopback unless you mean it)
  http_port     = 8080        // its port; 0 picks a free one (the URL is printed)
  refresh_hz    = 10          // at most this many updates per wall second to each page
  trail_length  = 200         // points of track drawn behind each vehicle
  boundary_host = 127.0.0.1   // pPathAssign's boundary server, for RE-PUSH BOUNDARY
  boundary_port = 9100        // default: pPathAssign's boundary_port in this file, else 9100

  // Buttons, as in MOOS-IvP's pMarineViewer: LABEL # VAR=value # VAR=value ...; a repeated
  // button_one line adds its pokes to button one (numbers are poked as doubles, "quoted" values
  // as strings). Default when none is given:
  button_one = DEPLOY # DEPLOY_ALL=true # MOOS_MANUAL_OVERRIDE_ALL=false # RETURN_ALL=false
  // button_two ... button_ten likewise. RETURN_ALL (RETURN_ALL=true) and RE-PUSH BOUNDARY are always there.

  // The action menu, as in pMarineViewer (none by default):
  // action = MENU_KEY=deploy # DEPLOY=true # RETURN=false
  // action = RETURN=true
}
"""
    interface = """\
SUBSCRIPTIONS:
  NODE_REPORT                    vehicles: NAME, X, Y (or LAT/LON), HDG, SPD, MODE, COLOR, ...
  VIEW_POLYGON, VIEW_SEGLIST, VIEW_POINT   markers (MOOS-IvP formats; active=false erases by label)
  OILSPILL_BOUNDARY              the boundary in force (pPathAssign)
  OILSPILL_FORECAST              each horizon of the latest forecast with its uncertainty band (pPathAssign);
                                 a new cycle= replaces the horizons shown
  OILSPILL_PHASE, OILSPILL_PHASE_<V>       fleet phase and the phase asked of each vehicle
  STARTING_POSITION_UPDATES_<V>  each vehicle's assigned start point
  OIL_PATH_UPDATES_<V>           each vehicle's containment loop
  OILSPILL_STATUS                pPathAssign's status line
  OIL_OBSERVATION                the vessels' oil samples (pOilSampler, bridged): filled = oil
  OIL_OBSERVED_EDGE, OIL_FUSION_SKILL   uFldOilFusion's observed edge points and skill line
  OILSPILL_WARNING, OILSPILL_DROPPED, OILSPILL_REJOINED, OIL_FUSION_WARNING   shown in the page's log

PUBLICATIONS:
  the variables of the configured buttons and actions, e.g. DEPLOY_ALL, MOOS_MANUAL_OVERRIDE_ALL, RETURN_ALL
  RETURN_ALL                     true, from the RETURN_ALL button
  (RE-PUSH BOUNDARY is a TCP line to pPathAssign, not a MOOS post)
"""

    def on_startup(self) -> None:
        """Also called by run_async before the base does: the page server needs the settings first."""
        if getattr(self, "scene", None) is not None:
            return
        self.settings = read_params(self.config, lambda cfg: read_settings(cfg, self.mission))
        warn_config(self.config, self.name)
        self.buttons: list[Button] = self.settings["buttons"]
        self.scene = Scene(trail_length=self.settings["trail_length"], grid=mission_grid(self.mission))
        self.actions: list[Button] = self.settings["actions"]
        self.setup = page_setup(self.scene.grid, self.buttons, self.mission.community if self.mission else "", "live",
                                self.start_time, self.actions, runs_a_spill(self.mission, self.config))
        self.db_up = False

    def on_connect(self) -> None:
        for key in SUBSCRIPTIONS:
            self.register(key)
        for pattern in WILDCARDS:
            self.register_wildcard(pattern)

    def on_new_mail(self, mail) -> None:
        for msg in mail:
            try:
                self.server.queue(self.scene.apply(msg.key, msg.value, msg.time, msg.community))
            except ViewError as exc:
                self.server.queue([self.scene.note("error", f"{msg.key} from {msg.sender}: {exc}", msg.time)])

    def iterate(self) -> None:
        """Tell the page when the MOOSDB goes away (the mission ended: the last picture stays) and
        when it answers again."""
        up = self.client.connected
        if up != self.db_up:
            where = f"the MOOSDB at {self.client.host}:{self.client.port}"
            now = self.moos_time()
            self.server.queue(self.scene.resume(f"{where} answers again: live", now) if up
                              else self.scene.end(f"{where} went away", now))
            self.db_up = up

    def snapshot(self) -> dict:
        return {**self.setup, **self.scene.snapshot(), "time": self.moos_time()}

    async def command(self, command: dict) -> None:
        """A page pressed a button or chose an action (by index: a page cannot poke anything that is
        not configured)."""
        now = self.moos_time()
        choices = {"button": self.buttons, "action": self.actions}.get(command["cmd"])
        if choices is not None:
            index = command.get("index")
            if isinstance(index, int) and 0 <= index < len(choices):
                button = choices[index]
                for key, value in button.pokes:
                    self.notify(key, value, time=now)
                pokes = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in button.pokes)
                self.server.queue([self.scene.note("poke", f"{button.label}: {pokes}", now)])
        elif command["cmd"] == "repush":
            await self.repush()

    async def repush(self) -> None:
        """Send the boundary in force to pPathAssign again as a pts={} line, so the fleet re-plans."""
        now = self.moos_time()
        if not self.scene.boundary_text:
            self.server.queue([self.scene.note("error", "RE-PUSH: no boundary in force yet", now)])
            return
        host, port = self.settings["boundary_host"], self.settings["boundary_port"]
        pusher = BoundaryPusher(host, port, connect_timeout=2.0, reply_timeout=5.0)
        try:
            seq = await pusher.push((self.scene.boundary_text.strip() + "\n").encode("utf-8"))
            note = self.scene.note("poke", f"RE-PUSH: pPathAssign at {host}:{port} accepted it as boundary {seq}", now)
        except (PushRejected, PushUnreachable, ValueError) as exc:
            note = self.scene.note("error", f"RE-PUSH to {host}:{port}: {exc}", now)
        finally:
            await pusher.close()
        self.server.queue([note])

    async def run_async(self) -> None:
        self.on_startup()
        port = self.settings["http_port"] if self.http_port_option is None else self.http_port_option
        self.server = MapServer(self.settings["http_host"], port, self.snapshot, self.command)
        await self.server.start()
        print(f"{self.name}: the map is at {self.server.url}", flush=True)
        flusher = asyncio.create_task(self.server.flush_every(1.0 / self.settings["refresh_hz"],
                                                              lambda: {"time": self.moos_time()}))
        try:
            await super().run_async()
        finally:
            flusher.cancel()
            self.server.queue(self.scene.end(f"{self.name} stopped", self.moos_time()))
            await self.server.shut_down({"time": self.moos_time()})

    @classmethod
    def main(cls, argv: list[str] | None = None) -> int:
        argv = sys.argv[1:] if argv is None else list(argv)
        extra = {a.partition("=")[0]: a.partition("=")[2] for a in argv if a.startswith(("--http_port=", "--replay="))}
        rest = [a for a in argv if not a.startswith(("--http_port=", "--replay="))]
        pages = {"--help", "-h", "--example", "-e", "--interface", "-i"}
        try:
            port = int(extra["--http_port"]) if "--http_port" in extra else None
        except ValueError:
            print(f"{cls.default_name}: --http_port={extra['--http_port']} is not a port number", file=sys.stderr)
            return 1
        if "--replay" in extra and not pages & set(rest):
            return replay_main(Path(extra["--replay"]), rest, port)
        return super().main(rest, http_port_option=port)


class Replay:
    """An alog played into a Scene on a clock the page controls (play, pause, speed, seek)."""

    def __init__(self, path: Path, trail_length: int = 200, grid=None):
        self.path = Path(path)
        self.trail_length, self.grid = trail_length, grid
        wanted = set(SUBSCRIPTIONS)
        prefixes = tuple(p.rstrip("*") for p in WILDCARDS)
        self.entries = [e for e in iter_alog(self.path) if not isinstance(e, float)
                        and (e.key in wanted or e.key.startswith(prefixes))]
        self.times = [e.time for e in self.entries]
        # every subscription but the reports and VIEW_* markers is the spill's
        self.spill = any(e.key not in REPORT_KEYS and e.key not in VIEW_KINDS for e in self.entries)
        self.end = self.times[-1] if self.times else 0.0
        self.t, self.speed, self.playing = 0.0, 1.0, True
        self.scene, self.applied = self._fresh(), 0

    def _fresh(self) -> Scene:
        return Scene(trail_length=self.trail_length, grid=self.grid)

    def clock(self) -> dict:
        return {"time": self.t, "replay": {"start": 0.0, "end": self.end, "t": self.t, "speed": self.speed,
                                           "playing": self.playing, "file": self.path.name}}

    def advance(self, wall_dt: float) -> list[dict]:
        """Move the clock on by `wall_dt` x speed (when playing); the updates of the entries passed."""
        if self.playing:
            self.t = min(self.end, self.t + wall_dt * self.speed)
            self.playing = self.t < self.end
        return self._apply_until(self.t)

    def seek(self, t: float) -> None:
        """Jump anywhere; going back rebuilds the picture from the start of the log."""
        t = min(max(0.0, float(t)), self.end)
        if t < self.t:
            self.scene, self.applied = self._fresh(), 0
        self.t = t
        self._apply_until(t)

    def _apply_until(self, t: float) -> list[dict]:
        stop = bisect.bisect_right(self.times, t)
        updates = []
        for entry in self.entries[self.applied:stop]:
            try:
                updates += self.scene.apply(entry.key, entry.value, entry.time, entry.community)
            except ViewError as exc:
                updates.append(self.scene.note("error", f"{self.path.name}:{entry.line}: {exc}", entry.time))
        self.applied = max(self.applied, stop)
        return updates


async def serve_replay(replay: Replay, host: str, port: int, refresh_hz: float, setup: dict,
                       ready: asyncio.Future | None = None, stop: asyncio.Event | None = None) -> None:
    """Serve `replay` until `stop` is set (`ready` gets the port once the page can be loaded);
    the page's play/pause/speed/seek commands steer the replay clock."""
    stop = stop or asyncio.Event()

    async def command(cmd: dict) -> None:
        if cmd["cmd"] == "seek" and isinstance(cmd.get("t"), (int, float)):
            replay.seek(cmd["t"])
            server.resend_snapshot()
        elif cmd["cmd"] == "play":
            replay.playing = True
            if replay.t >= replay.end:
                replay.seek(0.0)
                server.resend_snapshot()
        elif cmd["cmd"] == "pause":
            replay.playing = False
        elif cmd["cmd"] == "speed" and isinstance(cmd.get("speed"), (int, float)) and 0 < cmd["speed"] <= 1000:
            replay.speed = float(cmd["speed"])

    server = MapServer(host, port, lambda: {**setup, **replay.scene.snapshot(), **replay.clock()}, command)
    await server.start()
    print(f"pMarineViewer: replaying {replay.path} at {server.url}", flush=True)
    if ready is not None:
        ready.set_result(server.port)
    period = 1.0 / refresh_hz
    loop = asyncio.get_running_loop()
    last = loop.time()
    try:
        while not stop.is_set():
            now = loop.time()
            server.queue(replay.advance(now - last))
            last = now
            server.flush(replay.clock())
            try:
                await asyncio.wait_for(stop.wait(), period)
            except TimeoutError:
                pass
    finally:
        server.close()


def replay_main(alog: Path, rest: list[str], port: int | None) -> int:
    """`pMarineViewer [mission.moos] --replay=FILE.alog [--http_port=N]`: the mission file (optional)
    gives the viewer's settings and LatOrigin/LongOrigin."""
    positional = [a for a in rest if not a.startswith("-")]
    try:
        if len(positional) > 1 or len(positional) < len(rest):
            raise ValueError(f"with --replay only a mission file may be given, not {rest}")
        mission = read_mission(positional[0]) if positional else None
        block = mission.process_config(MarineViewer.default_name) if mission is not None else None
        settings = read_settings(block if block is not None else {}, mission)
        grid = mission_grid(mission)
        replay = Replay(alog, settings["trail_length"], grid)
    except (MissionFileError, AlogFormatError, ValueError, OSError) as exc:
        print(f"pMarineViewer: {exc}", file=sys.stderr)
        return 1
    setup = page_setup(grid, [], mission.community if mission else "", "replay",
                       spill=replay.spill or runs_a_spill(mission, block))

    async def runner():
        stop = asyncio.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            asyncio.get_running_loop().add_signal_handler(sig, stop.set)
        await serve_replay(replay, settings["http_host"], settings["http_port"] if port is None else port,
                           settings["refresh_hz"], setup, stop=stop)

    try:
        asyncio.run(runner())
    except OSError as exc:
        print(f"pMarineViewer: {exc}", file=sys.stderr)
        return 1
    return 0


@contextlib.contextmanager
def viewer_beside(mission_file: Path, http_port: int | None, *options: str):
    """pMarineViewer as its own process on a running mission's shoreside file (the demo's `--viewer`;
    `options` such as `--replay=FILE`); it prints its URL. Nothing is started when `http_port` is None."""
    if http_port is None:
        yield None
        return
    process = subprocess.Popen([str(Path(sys.executable).parent / "pMarineViewer"), Path(mission_file).name,
                                f"--http_port={http_port}", *options], cwd=Path(mission_file).parent)
    try:
        yield process
    finally:
        process.terminate()
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


main = MarineViewer.main
