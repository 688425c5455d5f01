"""MOOSDB benchmark: fan-in, fan-out, round trip, 1,000 idle clients, 1 MB binary.

Runs against any DB given as a command line (`{port}` is replaced by a free port), so the C++
MOOSDB can be measured side by side:

    python benchmarks/moosdb_bench.py                                  # the Python moosdb
    python benchmarks/moosdb_bench.py --db "MOOSDB --moos_port={port}" --db "moosdb --port {port}"
    python benchmarks/moosdb_bench.py --db "env PYTHONPATH=/tmp/old python -m moosdb_py.moosdb --port {port}" \
        --label before --db "python -m moosdb_py.moosdb --port {port}" --label after

Load comes from raw-socket clients with pre-encoded packets (100 notifies each, as a busy
C++ async client sends them) in separate processes, so the DB, not the clients, is measured.
The publishers stay at most WINDOW deliveries ahead of what the subscribers have read: without
that, a DB faster than the subscribers' process piles up mail until it drops them as stuck readers.
Besides rates it prints the DB's own CPU time per message (from /proc), which does not depend on
how busy the machine is.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import selectors
import shlex
import socket
import statistics
import struct
import subprocess
import sys
import time

from moosdb_py import codec
from moosdb_py.message import MOOSMsg

BATCH = 100
MIXED = 20            # variables taking turns in the mixed fan-in packets (as an app's outbox holds them)
WINDOW = 200_000      # deliveries the publishers may run ahead of the subscribers (a few MB per subscriber)
DEFAULT_DB = f"{sys.executable} -m moosdb_py.moosdb --port {{port}}"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def connect(port: int, name: str, timeout: float = 30.0) -> tuple[socket.socket, codec.StreamFramer]:
    """Raw async-client handshake; returns the socket and a framer holding any bytes after the welcome."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    hello = MOOSMsg("i", "S", "asynchronous", string=name, time=time.time())
    sock.sendall(codec.PROTOCOL_SLOT + codec.encode_packet([hello]))
    framer = codec.StreamFramer()
    while (packet := framer.next_unit()) is None:
        data = sock.recv(65536)
        if not data:
            raise ConnectionError(f"{name}: DB closed the connection during the handshake")
        framer.feed(data)
    welcome = codec.decode_packet(packet)[0]
    if welcome.msg_type != "W":
        raise ConnectionError(f"{name}: refused: {welcome.string}")
    return sock, framer


def send(sock: socket.socket, *msgs: MOOSMsg) -> None:
    sock.sendall(codec.encode_packet(msgs))


def timing() -> MOOSMsg:
    return MOOSMsg("T", "D", "_async_timing", 0.0, time=time.time())


def register(sock: socket.socket, name: str, *keys: str) -> None:
    send(sock, timing(), *(MOOSMsg("R", "D", key, 0.0, source=name, time=time.time()) for key in keys))


def count_messages(framer: codec.StreamFramer, data: bytes) -> int:
    """Mail messages in the packets completed by `data` (timing echoes not counted)."""
    framer.feed(data)
    n = 0
    while (packet := framer.next_unit()) is not None:
        n += struct.unpack_from("<i", packet, 4)[0]
        if packet[17:18] == b"T":
            n -= 1
    return n


def start_db(template: str) -> tuple[subprocess.Popen, int]:
    port = free_port()
    proc = subprocess.Popen(shlex.split(template.format(port=port)), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            sock, _ = connect(port, f"probe{time.monotonic_ns()}", timeout=2)
            sock.close()
            return proc, port
        except OSError:
            if proc.poll() is not None:
                raise RuntimeError(f"DB exited: {template}")
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError(f"DB did not start: {template}")


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


# -- throughput: publishers and subscribers in two processes ----------------------------------------
def publishers(port: int, n: int, tag: str, keys: tuple[str, ...], ready, go, stop, n_sub: int, sent,
               delivered) -> None:
    """n publishers, each writing `keys` in turn in packets of 100 notifies as fast as the DB takes them
    (and the subscribers read them)."""
    sel = selectors.DefaultSelector()
    pending = {}
    packets = []
    for i in range(n):
        sock, _ = connect(port, f"bench_pub{tag}_{i}")
        sock.setblocking(False)
        packets.append(codec.encode_packet([MOOSMsg.notification(keys[k % len(keys)], float(k), time=time.time(),
                                                                 source=f"bench_pub{tag}_{i}", msg_id=k)
                                            for k in range(BATCH)]))
        pending[i] = memoryview(packets[i])
        sel.register(sock, selectors.EVENT_WRITE, i)
    ready.set()
    go.wait()
    while not stop.is_set():
        if sent.value * n_sub - delivered.value > WINDOW:
            time.sleep(0.0002)
            continue
        for key, _ in sel.select(0.1):
            try:
                rest = pending[key.data][key.fileobj.send(pending[key.data]):]
            except BlockingIOError:
                continue
            if not rest:
                sent.value += BATCH
            pending[key.data] = rest if rest else memoryview(packets[key.data])
    for key in list(sel.get_map().values()):
        key.fileobj.close()


def subscribers(port: int, n: int, tag: str, keys: tuple[str, ...], ready, go, seconds: float, result,
                delivered) -> None:
    """n subscribers of `keys` counting what arrives in the measuring window (after a warm-up)."""
    sel = selectors.DefaultSelector()
    socks = []
    for i in range(n):
        sock, framer = connect(port, f"bench_sub{tag}_{i}")
        register(sock, f"bench_sub{tag}_{i}", *keys)
        sock.setblocking(False)
        sel.register(sock, selectors.EVENT_READ, framer)
        socks.append(sock)
    ready.set()
    go.wait()
    start = time.monotonic() + 0.5
    end = start + seconds
    counted = 0
    last_timing = time.monotonic()
    while (now := time.monotonic()) < end:
        for key, _ in sel.select(0.1):
            try:
                data = key.fileobj.recv(1 << 20)
            except BlockingIOError:
                continue
            got = count_messages(key.data, data)
            delivered.value += got
            if time.monotonic() >= start:
                counted += got
        if now - last_timing > 1.0:          # stay alive (client timeout)
            last_timing = now
            for sock in socks:
                sock.setblocking(True)
                send(sock, timing())
                sock.setblocking(False)
    result.value = counted
    for sock in socks:
        sock.close()


def throughput(pid: int, port: int, n_pub: int, n_sub: int, seconds: float,
               keys: tuple[str, ...] = ("BENCH",)) -> tuple[float, float]:
    """Messages delivered per second, and the DB's CPU time per delivered message (load-independent)."""
    ctx = mp.get_context("fork")
    subs_ready, pubs_ready, go, stop = ctx.Event(), ctx.Event(), ctx.Event(), ctx.Event()
    received = ctx.Value("q", 0)
    sent, delivered = ctx.RawValue("q", 0), ctx.RawValue("q", 0)
    tag = f"{n_pub}x{n_sub}x{len(keys)}"
    subs = ctx.Process(target=subscribers, args=(port, n_sub, tag, keys, subs_ready, go, seconds, received, delivered))
    subs.start()
    subs_ready.wait(300)
    pubs = ctx.Process(target=publishers,
                       args=(port, n_pub, tag, keys, pubs_ready, go, stop, n_sub, sent, delivered))
    pubs.start()
    pubs_ready.wait(300)
    go.set()
    time.sleep(0.5)                      # the subscribers' warm-up
    cpu = cpu_seconds(pid)
    subs.join(seconds + 30)
    cpu = cpu_seconds(pid) - cpu
    stop.set()
    pubs.join(10)
    return received.value / seconds, cpu / max(received.value, 1) * 1e6


# -- latency, idle clients, big binary --------------------------------------------------------------
def round_trips(port: int, key: str, payload, count: int, pause: float) -> list[float]:
    """Seconds from notify to the DB's delivery back to the publisher (subscribed to itself)."""
    sock, framer = connect(port, f"bench_rtt_{key}")
    register(sock, f"bench_rtt_{key}", key)
    samples = []
    last_timing = time.monotonic()
    for i in range(count):
        extra = []
        if time.monotonic() - last_timing > 1.0:
            last_timing = time.monotonic()
            extra = [timing()]
        t = time.perf_counter()
        send(sock, *extra, MOOSMsg.notification(key, payload, time=time.time(), source=f"bench_rtt_{key}", msg_id=i))
        while not any(m.key == key for m in _read_packet(sock, framer)):
            pass
        samples.append(time.perf_counter() - t)
        if pause:
            time.sleep(pause)
    sock.close()
    return samples


def _read_packet(sock: socket.socket, framer: codec.StreamFramer) -> list[MOOSMsg]:
    while (packet := framer.next_unit()) is None:
        framer.feed(sock.recv(1 << 20))
    return codec.decode_packet(packet)


def idle_clients(proc: subprocess.Popen, port: int, n: int, hold: float) -> tuple[float, float, int]:
    """Time to connect n clients, the DB's CPU while they idle (timing message every second), survivors."""
    t = time.monotonic()
    socks = []
    for i in range(n):
        try:
            socks.append(connect(port, f"idle{i}", timeout=300)[0])
        except OSError as exc:
            print(f"  idle client {i}: {exc}", file=sys.stderr)
            break
    accept_time = time.monotonic() - t
    cpu0, t0 = cpu_seconds(proc.pid), time.monotonic()
    ping = codec.encode_packet([timing()])
    while time.monotonic() - t0 < hold:
        for sock in socks:
            sock.sendall(ping)
        for sock in socks:
            sock.recv(65536)
        time.sleep(max(0.0, 1.0 - (time.monotonic() - t0) % 1.0))
    cpu = (cpu_seconds(proc.pid) - cpu0) / (time.monotonic() - t0)
    alive = 0
    for sock in socks:
        try:
            sock.sendall(ping)
            alive += 1
        except OSError:
            pass
        sock.close()
    return accept_time, cpu, alive


def bench(template: str, seconds: float, idle: int) -> dict:
    proc, port = start_db(template)
    out = {}
    try:
        for n in (1, 4, 16):
            rate, cost = throughput(proc.pid, port, n, 1, seconds)
            out[f"fan-in {n:>2} pub -> 1 sub (msg/s)"] = rate
            out[f"fan-in {n:>2} pub -> 1 sub (DB CPU us/msg)"] = cost
        rate, cost = throughput(proc.pid, port, 4, 1, seconds, tuple(f"BENCH_{k}" for k in range(MIXED)))
        out[f"fan-in  4 pub -> 1 sub, {MIXED} variables mixed (msg/s)"] = rate
        out[f"fan-in  4 pub -> 1 sub, {MIXED} variables mixed (DB CPU us/msg)"] = cost
        for n in (1, 8, 32):
            rate, cost = throughput(proc.pid, port, 1, n, seconds)
            out[f"fan-out 1 pub -> {n:>2} sub (deliveries/s)"] = rate
            out[f"fan-out 1 pub -> {n:>2} sub (DB CPU us/delivery)"] = cost
        rtt = round_trips(port, "RTT", 1.0, 300, 0.005)      # low rate: each one wakes both processes
        out["round trip p50 (ms)"] = statistics.median(rtt) * 1e3
        out["round trip p99 (ms)"] = statistics.quantiles(rtt, n=100)[98] * 1e3
        out["round trip back to back p50 (ms)"] = statistics.median(round_trips(port, "RTT2", 1.0, 2000, 0.0)) * 1e3
        big = round_trips(port, "BIG", os.urandom(1 << 20), 10, 0.0)
        out["1 MB binary round trip p50 (ms)"] = statistics.median(big) * 1e3
        accept, cpu, alive = idle_clients(proc, port, idle, 5.0)
        out[f"{idle} idle clients: connect all (s)"] = accept
        out[f"{idle} idle clients: DB CPU (% of a core)"] = cpu * 100
        out[f"{idle} idle clients: still connected"] = alive
    finally:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
    return out


def _label(template: str) -> str:
    words = shlex.split(template)
    return words[words.index("-m") + 1] if "-m" in words else os.path.basename(words[0])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", action="append", help="DB command line with {port}; repeat to compare (default: moosdb)")
    p.add_argument("--label", action="append", default=[], help="column heading of each --db, in order")
    p.add_argument("--seconds", type=float, default=2.0, help="measuring window per throughput figure")
    p.add_argument("--idle", type=int, default=1000, help="idle clients to connect")
    args = p.parse_args(argv)
    templates = args.db or [DEFAULT_DB]
    labels = args.label + [_label(t) for t in templates[len(args.label):]]
    results = [bench(t, args.seconds, args.idle) for t in templates]   # a --db may repeat (before/after runs)
    width = max(len(k) for r in results for k in r)
    print(f"{'':<{width}}  " + "  ".join(f"{label[:18]:>18}" for label in labels))
    for key in results[0]:
        print(f"{key:<{width}}  " + "  ".join(f"{r[key]:>18,.3f}" if isinstance(r[key], float) else f"{r[key]:>18}"
                                             for r in results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
