"""pHostInfo: tells the other apps of a community how the outside world reaches it.

The brokers put this community's address into their pings and acks; on a machine with several
interfaces, or behind a fixed address, they must not guess it themselves. The record also carries
pShare's input routes (learnt from PSHARE_INPUT_SUMMARY), so it is re-posted whenever those change.
"""
from __future__ import annotations

import fcntl
import ipaddress
import socket
import struct
from dataclasses import dataclass, fields

from .app import MOOSApp
from .config import Param, Params
from .formats import FormatError, parse_pairs
from .message import MOOSMsg


SIOCGIFADDR = 0x8915   # Linux ioctl: the IPv4 address of an interface


@dataclass
class HostRecord:
    """A host record (PHI_HOST_INFO, node broker pings and acks); field order is the wire order."""

    community: str = ""
    hostip: str = ""
    port_db: str = ""
    port_udp: str = ""
    pshare_iroutes: str = ""
    keyword: str = ""
    hostip_alts: str = ""
    timewarp: str = ""
    status: str = ""
    time: str = ""
    key: str = ""

    def spec(self) -> str:
        return ",".join(f"{f.name}={getattr(self, f.name)}" for f in fields(self) if getattr(self, f.name))

    @classmethod
    def parse(cls, text: str) -> "HostRecord":
        """Any field order, keys case-insensitive, a repeated key: the last wins; `vname` is an alias
        of `community`, the only required field; unknown fields are skipped."""
        names = {f.name for f in fields(cls)}
        values: dict[str, str] = {}
        try:
            pairs = parse_pairs(text)
        except FormatError as err:
            raise ValueError(f"host record: {err}") from None
        for key, value in pairs.items():
            key = "community" if key == "vname" else key
            if key in names:
                values[key] = value
        if not values.get("community"):
            raise ValueError(f"host record without community: '{text}'")
        return cls(**values)

    def iroutes(self) -> list[str]:
        return [r for r in self.pshare_iroutes.split("&") if r]


def iroutes_from_summary(summary: str) -> str:
    """PSHARE_INPUT_SUMMARY (`host:port,host:port`) -> the record's `host:port&host:port`."""
    return "&".join(r.strip() for r in summary.split(",") if r.strip())


def format_warp(warp: float) -> str:
    """`10`, not `10.0`, as pHostInfo writes it (at most two decimals)."""
    return f"{warp:.2f}".rstrip("0").rstrip(".")


def interface_addresses() -> dict[str, str]:
    """{interface name: IPv4 address} of every interface that has one (Linux ioctl; empty elsewhere)."""
    found: dict[str, str] = {}
    try:
        names = [name for _, name in socket.if_nameindex()]
    except OSError:
        return found
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for name in names:
            try:
                packed = fcntl.ioctl(sock.fileno(), SIOCGIFADDR, struct.pack("256s", name.encode()[:15]))
            except OSError:          # no IPv4 address on this interface
                continue
            found[name] = socket.inet_ntoa(packed[20:24])
    return found


@dataclass
class HostIP:
    """What pHostInfo decided: the address to advertise, every address found, and by interface."""

    best: str
    all: list[str]
    verbose: str


def choose_host_ip(addresses: dict[str, str], default_hostip: str, force: str) -> HostIP:
    """`force` wins outright; else the first non-loopback address; else `default_hostip`."""
    outside = [ip for ip in addresses.values() if not ipaddress.ip_address(ip).is_loopback]
    verbose = ",".join(f"LINUX_{name.upper()}={ip}" for name, ip in addresses.items())
    if force:
        return HostIP(force, [force], verbose)
    best = outside[0] if outside else default_hostip
    return HostIP(best, outside or [best], verbose)


class HostInfo(MOOSApp):
    """pHostInfo: posts this community's IP address, DB port and host record (PHI_HOST_INFO).

    The address is the one set by `default_hostip_force` if given, else the first non-loopback IPv4
    address of the machine's interfaces, else `default_hostip`. PHI_HOST_INFO is re-posted when
    pShare's input routes (PSHARE_INPUT_SUMMARY) change and on every HOST_INFO_REQUEST, so
    uFldNodeBroker and uFldShoreBroker always hand out the current routes.
    """

    default_name = "pHostInfo"
    parameters = Params(
        Param("default_hostip", str, "localhost", "address used when no non-loopback interface has one"),
        Param("default_hostip_force", str, "", "address used always, whatever the interfaces say"),
    )
    example_config = """\
ProcessConfig = pHostInfo
{
  AppTick   = 1
  CommsTick = 1

  // Address used when no non-loopback interface has one (default: localhost)
  default_hostip = localhost
  // Address used always, whatever the interfaces say (default: unset)
  default_hostip_force = localhost
}
"""
    interface = """\
SUBSCRIPTIONS:
  PSHARE_INPUT_SUMMARY  pShare's input routes (host:port,host:port): become pshare_iroutes
  HOST_INFO_REQUEST     any post: everything is posted again

PUBLICATIONS:
  PHI_HOST_IP           the address advertised, e.g. 192.168.1.5
  PHI_HOST_IP_ALL       every non-loopback address found (comma list; the forced one if forced)
  PHI_HOST_IP_VERBOSE   LINUX_<IFACE>=<ip>,... for every interface with an IPv4 address
  PHI_HOST_PORT_DB      the MOOSDB port (ServerPort)
  PHI_HOST_INFO         community=abe,hostip=192.168.1.5,port_db=9001,pshare_iroutes=localhost:9201,timewarp=10
"""

    def on_startup(self) -> None:
        v = self.read_settings()
        self.host_ip = choose_host_ip(interface_addresses(), v["default_hostip"], v["default_hostip_force"])
        mission = self.mission
        self.record = HostRecord(community=mission.community if mission else self.name,
                                 hostip=self.host_ip.best,
                                 port_db=str(mission.server_port if mission else self.client.port),
                                 timewarp=format_warp(self.time_warp))
        self.posted: str | None = None
        self.posts = 0

    def on_connect(self) -> None:
        self.register("PSHARE_INPUT_SUMMARY")
        self.register("HOST_INFO_REQUEST")
        self.posted = None    # a new DB (restart) hears everything again

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        for msg in mail:
            if msg.key == "PSHARE_INPUT_SUMMARY" and msg.is_string():
                self.record.pshare_iroutes = iroutes_from_summary(msg.string)
            elif msg.key == "HOST_INFO_REQUEST":
                self.posted = None

    def iterate(self) -> None:
        spec = self.record.spec()
        if spec == self.posted:
            return
        if self.posted is None:
            self.notify("PHI_HOST_IP", self.host_ip.best)
            self.notify("PHI_HOST_IP_ALL", ",".join(self.host_ip.all))
            self.notify("PHI_HOST_IP_VERBOSE", self.host_ip.verbose)
            self.notify("PHI_HOST_PORT_DB", self.record.port_db)
        self.notify("PHI_HOST_INFO", spec)
        self.posted = spec
        self.posts += 1

    def status_fields(self) -> dict:
        return {"hostip": self.host_ip.best, "pshare_iroutes": self.record.pshare_iroutes or "none",
                "posts": self.posts}


main = HostInfo.main
