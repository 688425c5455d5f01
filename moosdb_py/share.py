"""pShare: forwards variables between MOOS communities over UDP, one datagram per message.

A datagram is one serialised CMOOSMsg exactly as the MOOS wire protocol lays it
out (`moosdb_py.codec`), so these datagrams are the ones the C++ pShare sends and
receives.  The routing table (`ShareTable`), the config and PSHARE_CMD parsers and
the datagram codec are pure; the `Share` MOOSApp only adds the UDP sockets.
"""
from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import sys
from dataclasses import dataclass, field

from moosdb_py.app import MOOSApp
from moosdb_py.codec import CodecError, decode_message, encode_message
from moosdb_py.message import NOTIFY, MOOSMsg
from moosdb_py.config import Param, Params
from moosdb_py.formats import FormatError, parse_pairs, wild_match

log = logging.getLogger(__name__)

MAX_DATAGRAM = 48 * 1024  # the C++ pShare's largest payload
DEFAULT_MULTICAST_ADDRESS = "224.1.1.11"
DEFAULT_MULTICAST_BASE_PORT = 24460
MULTICAST_CHANNELS = 256
KNOWN_OUTPUT_FIELDS = {"src_name", "dest_name", "route", "frequency", "cmd"}
KNOWN_INPUT_FIELDS = {"route", "cmd"}
SHARE_PARAMS = Params(
    Param("input", list, [], "`route = host:port[ & ...]`: listen for other communities' datagrams (repeatable)"),
    Param("output", list, [], "`src_name = X, dest_name = Y, route = host:port[ & ...], frequency = Hz` or "
                              "`X->Y:host:port@Hz` (repeatable)"),
    Param("multicast_address", str, DEFAULT_MULTICAST_ADDRESS, "the group multicast_N routes use"),
    Param("multicast_base_port", str, str(DEFAULT_MULTICAST_BASE_PORT), "multicast_N is this port + N"),
)


class ShareConfigError(ValueError):
    """An output/input line or a PSHARE_CMD that cannot be understood."""


class DatagramTooLarge(ValueError):
    """A value that would not fit in one datagram; it is reported, never cut or dropped silently."""


class MalformedDatagram(ValueError):
    """Bytes that arrived on an input route but are not one MOOS notify message."""


# --- datagram codec ---------------------------------------------------------------------------

def encode_datagram(msg: MOOSMsg, dest_name: str, community: str) -> bytes:
    """The datagram for `msg` renamed to `dest_name`; source, aux, time and id are kept."""
    out = msg.copy()     # (dataclasses.replace costs twice the encoding itself)
    out.msg_type, out.key, out.community = NOTIFY, dest_name, community
    wire = encode_message(out)
    if len(wire) > MAX_DATAGRAM:
        raise DatagramTooLarge(
            f"{msg.key} -> {dest_name}: {len(wire)} bytes serialised, more than one datagram "
            f"carries ({MAX_DATAGRAM}); not forwarded")
    return wire


def decode_datagram(data: bytes) -> MOOSMsg:
    """One datagram -> the notify message it carries; anything else raises MalformedDatagram."""
    try:
        msg, end = decode_message(data)
    except (CodecError, ValueError) as exc:  # struct errors on short input are ValueErrors too
        raise MalformedDatagram(f"not a MOOS message ({len(data)} bytes): {exc}") from None
    if end != len(data):
        raise MalformedDatagram(f"{len(data) - end} stray bytes after the message")
    if msg.msg_type != NOTIFY:
        raise MalformedDatagram(f"message type {msg.msg_type!r}, only notifies ('N') are shared")
    if not msg.key:
        raise MalformedDatagram("notify without a variable name")
    return msg


# --- routes and config lines ------------------------------------------------------------------

@dataclass(frozen=True)
class Route:
    """Where datagrams go to (outputs) or are listened for (inputs)."""

    host: str
    port: int
    channel: int | None = None  # multicast channel number, None for plain UDP

    @property
    def multicast(self) -> bool:
        return self.channel is not None

    def __str__(self) -> str:
        address = f"{self.host}:{self.port}"
        return f"{address}:multicast_{self.channel}" if self.multicast else address


def parse_route(text: str, multicast_address: str = DEFAULT_MULTICAST_ADDRESS,
                base_port: int = DEFAULT_MULTICAST_BASE_PORT) -> Route:
    """`host:port` or `multicast_N` (the multicast group at base port + N)."""
    text = text.strip()
    if text.startswith("multicast_"):
        channel = text[len("multicast_"):]
        if not channel.isdigit() or int(channel) >= MULTICAST_CHANNELS:
            raise ShareConfigError(f"route '{text}': multicast channel must be 0..{MULTICAST_CHANNELS - 1}")
        return Route(multicast_address, base_port + int(channel), int(channel))
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ShareConfigError(f"route '{text}' is not host:port or multicast_N")
    return Route(host, int(port))


def _fields(text: str, known: set[str], warnings: list[str]) -> dict[str, str]:
    """`a=1,b=2` with every blank removed, as MOOS config lines reach an app."""
    try:
        pairs = parse_pairs("".join(text.split()))
    except FormatError as err:
        raise ShareConfigError(f"{err} in '{text}'") from None
    warnings += [f"'{key}' is not a pShare field; ignored in '{text}'" for key in pairs if key not in known]
    return pairs


@dataclass(frozen=True)
class OutputSpec:
    src_name: str
    dest_name: str
    routes: tuple[str, ...]
    frequency: float = 0.0


def parse_output(text: str, warnings: list[str]) -> list[OutputSpec]:
    """`src_name=X,dest_name=Y,route=a:1&b:2[,frequency=Hz]`, or the shorthand `X->Y:host:port@Hz & ...`."""
    if "route" not in text.lower():
        return parse_shorthand_output(text)
    pairs = _fields(text, KNOWN_OUTPUT_FIELDS, warnings)
    src = pairs.get("src_name", "")
    if not src:
        raise ShareConfigError(f"output '{text}': src_name is required")
    routes = tuple(r for r in pairs.get("route", "").split("&") if r)
    if not routes:
        raise ShareConfigError(f"output '{text}': route is required")
    return [OutputSpec(src, pairs.get("dest_name") or src, routes, _frequency(pairs.get("frequency", "0"), text))]


def parse_shorthand_output(text: str) -> list[OutputSpec]:
    """`X->Y:165.45.3.61:9000@0.5 & Z:multicast_8`: one spec per route (each may rename and limit)."""
    src, sep, rest = "".join(text.split()).partition("->")
    if not sep or not src or not rest:
        raise ShareConfigError(f"output '{text}' is neither src_name=..,route=.. nor X->[Y:]host:port")
    specs = []
    for item in rest.split("&"):
        route_text, _, freq = item.partition("@")
        parts = route_text.split(":")
        if parts[-1].startswith("multicast_"):
            dest, route = (parts[0], parts[1]) if len(parts) == 2 else (src, parts[0])
            if len(parts) > 2:
                raise ShareConfigError(f"output '{text}': too many parts in '{item}'")
        elif len(parts) in (2, 3):
            dest = parts[0] if len(parts) == 3 else src
            route = ":".join(parts[-2:])
        else:
            raise ShareConfigError(f"output '{text}': '{item}' is not [dest:]host:port or [dest:]multicast_N")
        specs.append(OutputSpec(src, dest, (route,), _frequency(freq or "0", text)))
    return specs


def _frequency(text: str, line: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ShareConfigError(f"'{line}': frequency '{text}' is not a number") from None
    if not value >= 0.0 or value == float("inf"):
        raise ShareConfigError(f"'{line}': frequency must be >= 0 Hz")
    return value


def parse_input(text: str, warnings: list[str]) -> tuple[str, ...]:
    """`route=localhost:9201 & multicast_9` -> the routes."""
    routes = tuple(r for r in _fields(text, KNOWN_INPUT_FIELDS, warnings).get("route", "").split("&") if r)
    if not routes:
        raise ShareConfigError(f"input '{text}': route is required")
    return routes


def parse_command(text: str, warnings: list[str]) -> tuple[list[OutputSpec], tuple[str, ...]]:
    """A PSHARE_CMD: `cmd=output,...` gives output specs, `cmd=input,route=..` input routes."""
    cmd = _fields(text, KNOWN_OUTPUT_FIELDS, []).get("cmd", "").lower()
    if cmd == "output":
        return parse_output(text, warnings), ()
    if cmd == "input":
        return [], parse_input(text, warnings)
    raise ShareConfigError(f"'{text}': cmd must be output or input")


# --- the routing table ------------------------------------------------------------------------

def is_wildcard(src_name: str) -> bool:
    return any(c in src_name for c in "*?:")


@dataclass
class Output:
    """One share: variable `src` goes to `route` as `dest`."""

    src: str
    dest: str
    route: Route
    frequency: float = 0.0
    last_sent: float | None = field(default=None, compare=False)

    def due(self, now: float) -> bool:
        return self.frequency <= 0.0 or self.last_sent is None or now - self.last_sent >= 1.0 / self.frequency


@dataclass
class WildcardOutput:
    """`src_name=VAR_PATTERN[:APP_PATTERN]`; each matching variable becomes a plain Output on first sight."""

    var_pattern: str
    app_pattern: str
    dest: str  # prefix; "" = keep the name; "^" = keep only what '*' matched
    route: Route
    frequency: float = 0.0

    def dest_for(self, key: str) -> str:
        if self.dest == "^" and self.var_pattern.count("*") == 1:
            if self.var_pattern.startswith("*"):
                return key[: len(key) - len(self.var_pattern) + 1]
            if self.var_pattern.endswith("*"):
                return key[len(self.var_pattern) - 1:]
        return self.dest + key


@dataclass
class Subscription:
    """What pShare must register for after a change to its table."""

    var: str
    app_pattern: str | None = None  # None: plain register; else a wildcard register


class ShareTable:
    """The outputs and inputs of one pShare, and the forwarding decisions, free of I/O."""

    def __init__(self, multicast_address: str = DEFAULT_MULTICAST_ADDRESS,
                 base_port: int = DEFAULT_MULTICAST_BASE_PORT):
        self.multicast_address = multicast_address
        self.base_port = base_port
        self.outputs: dict[str, list[Output]] = {}
        self.wildcards: list[WildcardOutput] = []
        self.inputs: list[Route] = []

    def route(self, text: str) -> Route:
        return parse_route(text, self.multicast_address, self.base_port)

    def add_output(self, spec: OutputSpec) -> list[Subscription]:
        """Add a share (an exact repeat changes nothing); returns the new subscriptions it needs."""
        routes = [self.route(r) for r in spec.routes]
        subs: list[Subscription] = []
        if is_wildcard(spec.src_name):
            var_pattern, _, app_pattern = spec.src_name.partition(":")
            dest = "" if any(c in spec.dest_name for c in "*?") else spec.dest_name
            for route in routes:
                share = WildcardOutput(var_pattern, app_pattern or "*", dest, route, spec.frequency)
                if share not in self.wildcards:
                    self.wildcards.append(share)
                    subs.append(Subscription(share.var_pattern, share.app_pattern))
            return subs
        existing = self.outputs.setdefault(spec.src_name, [])
        for route in routes:
            share = Output(spec.src_name, spec.dest_name, route, spec.frequency)
            if share not in existing:
                existing.append(share)
                subs.append(Subscription(spec.src_name))
        return subs

    def add_input(self, route_text: str) -> Route | None:
        """A new input route to listen on, or None if already listening there."""
        route = self.route(route_text)
        if route in self.inputs:
            return None
        self.inputs.append(route)
        return route

    def remove_input(self, route: Route) -> None:
        self.inputs.remove(route)

    def subscriptions(self) -> list[Subscription]:
        """Everything to register for, e.g. again after a reconnect."""
        plain = [Subscription(src) for src in self.outputs]
        return plain + [Subscription(w.var_pattern, w.app_pattern) for w in self.wildcards]

    def is_shared(self, key: str) -> bool:
        """True for a variable this pShare forwards: such a datagram is not posted (stops echo loops)."""
        return key in self.outputs or any(wild_match(w.var_pattern, key) for w in self.wildcards)

    def forward(self, msg: MOOSMsg, now: float) -> list[Output]:
        """The shares a new value of `msg.key` goes out on now (frequency limits applied)."""
        shares = self.outputs.get(msg.key)
        if shares is None:
            matching = [w for w in self.wildcards
                        if wild_match(w.var_pattern, msg.key) and wild_match(w.app_pattern, msg.source)]
            if not matching:
                return []
            shares = self.outputs[msg.key] = [Output(msg.key, w.dest_for(msg.key), w.route, w.frequency)
                                              for w in matching]
        due = [s for s in shares if s.due(now)]
        for share in due:
            share.last_sent = now
        return due

    def output_summary(self) -> str:
        """PSHARE_OUTPUT_SUMMARY: `src->dest:host:port & dest2:host:port, src2->...`, sorted by src."""
        return ", ".join(
            f"{src}->" + " & ".join(f"{s.dest}:{s.route}" for s in shares)
            for src, shares in sorted(self.outputs.items()) if shares
        )

    def input_summary(self) -> str:
        """PSHARE_INPUT_SUMMARY: `host:port,host:port`."""
        return ",".join(str(r) for r in self.inputs)


# --- the MOOSApp shell: UDP sockets -------------------------------------------------------------

SUMMARY_PERIOD = 1.0  # seconds (MOOS time) between PSHARE_*_SUMMARY posts
RECV_BUFFER = 64 * 1024


class Share(MOOSApp):
    """pShare: forwards MOOS variables to other MOOS communities over UDP, and posts what other
    communities send it.  Each forwarded message keeps its source, originating community and time
    stamp; only its name changes (src_name -> dest_name).  A received datagram whose variable this
    pShare itself forwards is dropped (that stops echo loops); a malformed one is logged and dropped.

    Usage: pShare mission.moos [alias] [-i=host:port,...] [-o=X->Y:host:port@Hz,...]
    Routes come from its ProcessConfig block, the -i=/-o= switches and PSHARE_CMD.
    One datagram per message, laid out as a serialised CMOOSMsg, as the C++ pShare sends it.
    """

    default_name = "pShare"
    posts_iteration_load = False   # a core-MOOS app: no ITER_GAP / ITER_LEN
    parameters = SHARE_PARAMS
    example_config = """\
ProcessConfig = pShare
{
  AppTick   = 4
  CommsTick = 4

  // Listen for other communities' datagrams (repeatable; '&' separates routes).
  // localhost:P listens on loopback only; 0.0.0.0:P on every interface.
  input  = route = localhost:9201

  // Forward X as Y (repeatable).  dest_name defaults to src_name; frequency (Hz,
  // default 0 = every change) limits the rate on each route.
  output = src_name = X, dest_name = Y, route = localhost:9200 & multicast_8, frequency = 0
  // Wildcards: src_name = NAV_*  (dest_name is then a prefix; dest_name = ^ keeps what * matched);
  //            src_name = NAV_*:uSim*  also matches the publishing app.
  // Shorthand: output = X->Y:localhost:9200@2 & Z:multicast_8

  multicast_address   = 224.1.1.11   // the group multicast_N routes use
  multicast_base_port = 24460        // multicast_N is this port + N
}
"""
    interface = """\
SUBSCRIPTIONS:
  PSHARE_CMD (<ALIAS>_CMD under an alias)
      cmd=output,src_name=X,dest_name=Y,route=host:port[&route...][,frequency=Hz]
      cmd=input,route=host:port[&route...]
  every output's src_name (wildcard outputs: a wildcard registration)

PUBLICATIONS:
  PSHARE_OUTPUT_SUMMARY  src->dest:host:port & dest2:host:port, src2->...   (once a second)
  PSHARE_INPUT_SUMMARY   host:port,host:port
  every variable received from another community, as sent (source, community, time kept)
"""

    command_line: tuple[str, ...] = ()  # -o=... / -i=... switches given to `main`

    @classmethod
    def main(cls, argv: list[str] | None = None) -> int:
        """The MOOS command line, plus pShare's `-o=X->Y:host:port,...` and `-i=host:port,...` routes."""
        argv = sys.argv[1:] if argv is None else list(argv)
        switches = tuple(a for a in argv if a.partition("=")[0] in ("-o", "-i", "--output", "--input"))
        bare = [a.partition("=")[0] for a in switches if not a.partition("=")[2].strip()]
        if bare:   # `-i` alone would otherwise start a pShare that listens nowhere
            example = "-i=localhost:9201" if bare[0] in ("-i", "--input") else "-o=X->Y:localhost:9200"
            print(f"{cls.default_name}: {bare[0]} needs routes, e.g. {example} "
                  "(for the interface page: --interface)", file=sys.stderr)
            return 1
        return super().main([a for a in argv if a not in switches], command_line=switches)

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # Mail is forwarded as it arrives, not at the next AppTick (the C++ pShare's
        # REGULAR_ITERATE_AND_COMMS_DRIVEN_MAIL): a bridge should add no tick of latency.
        self.client.on_mail = self.on_new_mail
        # Here, not in on_startup: close_sockets must work after a start-up that failed early.
        self.listeners: dict[Route, socket.socket] = {}
        self.sender: socket.socket | None = None

    def on_startup(self) -> None:
        cfg = self.config
        base_entry = cfg.entry("multicast_base_port")
        base_port = base_entry.value if base_entry and base_entry.value else str(DEFAULT_MULTICAST_BASE_PORT)
        if not base_port.strip().isdigit():
            raise base_entry.source.error(f"multicast_base_port: '{base_port}' is not a port number")
        self.table = ShareTable((cfg.get("multicast_address") or DEFAULT_MULTICAST_ADDRESS).strip(),
                                int(base_port))
        self.counts = dict.fromkeys(("sent", "received", "echo", "malformed", "oversize", "send_errors"), 0)
        self.last_summary: float | None = None
        self.addresses: dict[Route, tuple] = {}
        self.sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sender.setblocking(False)
        self.sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        warnings: list[str] = []
        for key, apply in (("output", self.apply_output), ("input", self.apply_input)):
            for entry in [e for e in cfg.entries if e.key.lower() == key]:
                try:
                    apply(entry.value, warnings)
                except (ShareConfigError, OSError) as exc:
                    raise entry.source.error(f"{key}: {exc}") from None
        for switch in self.command_line:
            flag, _, routes = switch.partition("=")
            apply = self.apply_output if flag in ("-o", "--output") else self.apply_input
            for item in filter(None, routes.split(",")):
                try:
                    apply(item if flag in ("-o", "--output") else f"route={item}", warnings)
                except (ShareConfigError, OSError) as exc:
                    raise ValueError(f"command line {flag}: {exc}") from None
        for warning in warnings:
            log.warning("%s: %s", self.name, warning)

    def apply_output(self, text: str, warnings: list[str]) -> None:
        for spec in parse_output(text, warnings):
            self.subscribe(self.table.add_output(spec))

    def apply_input(self, text: str, warnings: list[str]) -> None:
        for route_text in parse_input(text, warnings):
            self.listen(route_text)

    def subscribe(self, subs: list[Subscription]) -> None:
        for sub in subs:
            if sub.app_pattern is None:
                self.register(sub.var)
            else:
                self.register_wildcard(sub.var, sub.app_pattern)

    def listen(self, route_text: str) -> None:
        route = self.table.add_input(route_text)
        if route is None:
            return
        try:
            self.listeners[route] = open_listener(route)
        except OSError as exc:
            self.table.remove_input(route)
            raise OSError(f"cannot listen on {route}: {exc.strerror or exc}") from None
        asyncio.get_running_loop().add_reader(self.listeners[route].fileno(), self.on_datagrams, route)

    def on_connect(self) -> None:
        self.register(self.command_key)
        self.subscribe(self.table.subscriptions())

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        now = self.moos_time()
        for msg in mail:
            if msg.key == self.command_key:
                if msg.time < self.start_time:  # as the C++ pShare: a command from before we started is stale
                    log.info("%s: ignoring %s posted before start-up: %s", self.name, msg.key, msg.string)
                else:
                    self.on_command(msg)
                continue
            for share in self.table.forward(msg, now):
                self.send(msg, share)

    def on_command(self, msg: MOOSMsg) -> None:
        warnings: list[str] = []
        try:
            specs, inputs = parse_command(msg.string, warnings)
            for spec in specs:
                self.subscribe(self.table.add_output(spec))
            for route_text in inputs:
                self.listen(route_text)
        except (ShareConfigError, OSError) as exc:
            log.error("%s: %s from %s rejected: %s", self.name, self.command_key, msg.source, exc)
        for warning in warnings:
            log.warning("%s: %s from %s: %s", self.name, self.command_key, msg.source, warning)

    def send(self, msg: MOOSMsg, share: Output) -> None:
        try:
            datagram = encode_datagram(msg, share.dest, msg.community or self.client.community)
        except DatagramTooLarge as exc:
            self.counts["oversize"] += 1
            log.error("%s: %s", self.name, exc)
            return
        try:
            address = self.addresses.get(share.route) or self.resolve(share.route)
            self.sender.sendto(datagram, address)
            self.counts["sent"] += 1
        except OSError as exc:  # unresolvable host, full buffer, unreachable network
            self.counts["send_errors"] += 1
            log.warning("%s: %s -> %s: send failed: %s", self.name, share.dest, share.route, exc)

    def resolve(self, route: Route) -> tuple:
        info = socket.getaddrinfo(route.host, route.port, socket.AF_INET, socket.SOCK_DGRAM)
        self.addresses[route] = info[0][4]
        return self.addresses[route]

    def on_datagrams(self, route: Route) -> None:
        sock = self.listeners[route]
        while True:
            try:
                data, sender = sock.recvfrom(RECV_BUFFER)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                log.warning("%s: receive on %s failed: %s", self.name, route, exc)
                return
            self.on_datagram(data, f"{sender[0]}:{sender[1]}", route)

    def on_datagram(self, data: bytes, sender: str, route: Route) -> None:
        try:
            msg = decode_datagram(data)
        except MalformedDatagram as exc:
            self.counts["malformed"] += 1
            log.warning("%s: malformed datagram from %s on %s dropped: %s", self.name, sender, route, exc)
            return
        if self.table.is_shared(msg.key):
            self.counts["echo"] += 1
            return
        self.counts["received"] += 1
        self.post_message(msg)

    def iterate(self) -> None:
        now = self.moos_time()
        if self.last_summary is None or now - self.last_summary >= SUMMARY_PERIOD:
            self.last_summary = now
            self.notify("PSHARE_OUTPUT_SUMMARY", self.table.output_summary())
            self.notify("PSHARE_INPUT_SUMMARY", self.table.input_summary())

    def post_message(self, msg: MOOSMsg) -> None:
        """Post a received message as it was sent, like C++ `Post(msg, keep_source=true)`."""
        self.client.published.add(msg.key)
        self.client.post(msg, keep_source=True)

    async def run_async(self) -> None:
        try:
            await super().run_async()
        finally:
            self.close_sockets()

    def close_sockets(self) -> None:
        loop = asyncio.get_running_loop()
        for sock in self.listeners.values():
            with contextlib.suppress(ValueError, OSError):
                loop.remove_reader(sock.fileno())
            sock.close()
        self.listeners.clear()
        if self.sender is not None:
            self.sender.close()

    def status_fields(self) -> dict:
        return dict(self.counts)


def open_listener(route: Route) -> socket.socket:
    """A non-blocking UDP socket bound to an input route (a multicast one joins its group)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        if route.multicast:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(("", route.port))
            group = socket.inet_aton(socket.gethostbyname(route.host))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, group + socket.inet_aton("0.0.0.0"))
        else:
            sock.bind((route.host, route.port))
        sock.setblocking(False)
    except OSError:
        sock.close()
        raise
    return sock


main = Share.main
