"""Free loopback ports for launching communities (MOOSDB, pShare, servers) side by side."""
from __future__ import annotations

import socket

_HANDED_OUT: set[tuple[int, int]] = set()


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A loopback port free right now for TCP (MOOSDB, boundary server) or UDP (pShare).

    The probe is closed before the app binds, so the kernel may offer the same port again (8 times
    in 300 draws, measured): a port is never handed out twice by this process, or two MOOSDBs or two
    pShares of one mission would be given one port.
    """
    while True:
        with socket.socket(socket.AF_INET, kind) as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if (kind, port) not in _HANDED_OUT:
            _HANDED_OUT.add((kind, port))
            return port
