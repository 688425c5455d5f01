"""Free ports (moosdb_py.ports, used by the demo and the tests): one mission never gets one port twice (the kernel offers a closed probe's port again)."""
import socket

import pytest

from moosdb_py.ports import free_port


@pytest.mark.parametrize("kind", [socket.SOCK_STREAM, socket.SOCK_DGRAM])
def test_free_ports_are_never_handed_out_twice(kind):
    ports = [free_port(kind) for _ in range(300)]   # unchecked, ~8 repeats in 300 (measured)
    assert len(set(ports)) == len(ports)
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", ports[-1]))            # and each one was free
