"""Launch missions/fleet: a shoreside and N vehicles, each its own MOOS community on its own ports.

    python missions/fleet/launch.py [WARP] [--vehicles N] [--moos-port P] [--pshare-port Q] [--dir D]

As MOOS-IvP's launch.sh scripts do, this expands the templates with nsplug (one
targ_<vname>.moos/.bhv per vehicle, from meta_vehicle.*; targ_shoreside.moos from
meta_shoreside.moos) and then starts `pAntler` on each targ file.  Vehicle i
(1-based) uses MOOSDB port P+i and pShare port Q+i; the shoreside uses P and Q.
Ctrl-C (or SIGTERM) stops every community.  `--generate-only` writes the targ
files and exits, for launching the communities by hand or on other hosts.
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from moosdb_py.nsplug import preprocess
from moosdb_py.source import MissionFileError

HERE = Path(__file__).resolve().parent
VEHICLE_NAMES = ("abe", "ben", "cal", "deb", "eve", "fin", "gil", "hal", "ike", "jan", "kim", "lou")
SURVEY_HALF_SIDE = 30.0  # metres; each vehicle surveys a square about a point south of its start
VEHICLE_SPACING = 80.0


@dataclass(frozen=True)
class Community:
    name: str
    moos_port: int
    pshare_port: int
    defines: dict[str, str]

    @property
    def moos_file(self) -> str:
        return f"targ_{self.name}.moos"


def vehicle_names(count: int) -> list[str]:
    if not 1 <= count <= len(VEHICLE_NAMES):
        raise ValueError(f"--vehicles must be 1..{len(VEHICLE_NAMES)}, got {count}")
    return list(VEHICLE_NAMES[:count])


def survey_points(x: float, y: float) -> str:
    cy = y - 60.0
    d = SURVEY_HALF_SIDE
    corners = [(x - d, cy + d), (x + d, cy + d), (x + d, cy - d), (x - d, cy - d)]
    return ":".join(f"{px:g},{py:g}" for px, py in corners)


def plan(vehicles: int, warp: float, moos_port: int = 9000, pshare_port: int = 9200,
         shore_ip: str = "localhost") -> list[Community]:
    """The shoreside first, then each vehicle, with the nsplug macros its templates need."""
    common = {"WARP": f"{warp:g}"}
    shore = Community("shoreside", moos_port, pshare_port,
                      {**common, "MOOS_PORT": str(moos_port), "PSHARE_PORT": str(pshare_port)})
    communities = [shore]
    for i, vname in enumerate(vehicle_names(vehicles), start=1):
        x, y = (i - 1) * VEHICLE_SPACING, 0.0
        communities.append(Community(vname, moos_port + i, pshare_port + i, {
            **common, "VNAME": vname, "MOOS_PORT": str(moos_port + i), "PSHARE_PORT": str(pshare_port + i),
            "SHORE_IP": shore_ip, "SHORE_PSHARE": str(pshare_port),
            "START_POS": f"{x:g},{y:g}", "SURVEY_PTS": survey_points(x, y),
        }))
    return communities


def expand(template: Path, defines: dict[str, str], target: Path) -> None:
    lines = preprocess(template, defines)
    target.write_text("".join(line.text + "\n" for line in lines))


def generate(communities: list[Community], out_dir: Path) -> list[Path]:
    """Write every targ file into out_dir; returns the .moos files, shoreside first."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = []
    for community in communities:
        template = "meta_shoreside.moos" if community.name == "shoreside" else "meta_vehicle.moos"
        expand(HERE / template, community.defines, out_dir / community.moos_file)
        if community.name != "shoreside":
            expand(HERE / "meta_vehicle.bhv", community.defines, out_dir / f"targ_{community.name}.bhv")
        files.append(out_dir / community.moos_file)
    return files


def launch(files: list[Path], antler_args: list[str]) -> int:
    """One pAntler per community, each in its own process group; stop them all on a signal."""
    antler = [sys.executable, "-m", "moosdb_py.antler"]  # pAntler of this interpreter's install
    children = [subprocess.Popen([*antler, *antler_args, f.name], cwd=f.parent, start_new_session=True)
                for f in files]
    stopping = False

    def stop(signum, frame):  # noqa: ARG001 - signal handler signature
        nonlocal stopping
        stopping = True

    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    while not stopping and all(c.poll() is None for c in children):
        time.sleep(0.2)
    for child in children:
        if child.poll() is None:
            os.killpg(child.pid, signal.SIGTERM)
    for child in children:
        try:
            child.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(child.pid, signal.SIGKILL)
            child.wait()
    failed = [f.name for f, c in zip(files, children) if c.returncode not in (0, -signal.SIGTERM)]
    if failed:
        print(f"launch: pAntler ended with an error for {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("warp", nargs="?", type=float, default=1.0, help="MOOSTimeWarp (default 1)")
    parser.add_argument("--vehicles", type=int, default=3, help="number of vehicles (default 3)")
    parser.add_argument("--moos-port", type=int, default=9000, help="shoreside MOOSDB port; vehicle i uses +i")
    parser.add_argument("--pshare-port", type=int, default=9200, help="shoreside pShare port; vehicle i uses +i")
    parser.add_argument("--shore-ip", default="localhost", help="address vehicles reach the shoreside at")
    parser.add_argument("--dir", type=Path, default=Path.cwd() / "fleet_run", help="where targ files and logs go")
    parser.add_argument("--generate-only", action="store_true", help="write the targ files and exit")
    parser.add_argument("--one-process", action="store_true", help="pAntler --one-process for every community")
    args = parser.parse_args(argv)
    if args.warp <= 0:
        parser.error("the time warp must be > 0")
    try:
        files = generate(plan(args.vehicles, args.warp, args.moos_port, args.pshare_port, args.shore_ip), args.dir)
    except (ValueError, MissionFileError) as exc:
        print(f"launch: {exc}", file=sys.stderr)
        return 2
    print("\n".join(str(f) for f in files))
    if args.generate_only:
        return 0
    return launch(files, ["--one-process"] if args.one_process else [])


if __name__ == "__main__":
    sys.exit(main())
