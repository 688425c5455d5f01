"""The boundary push against a real TCP listener playing pPathAssign, including its restart."""
import asyncio
import json

import pytest
from shapely.geometry import Polygon

from oilspill_moos.forecaster.push import BoundaryPusher, PushRejected, PushUnreachable, parse_reply
from oilspill_moos.messages import boundary_line

SQUARE = Polygon([(-88.4, 28.7), (-88.3, 28.7), (-88.3, 28.8), (-88.4, 28.8)])


class Listener:
    """Answers each line ``OK <n>`` (or ``ERR`` for lines containing 'bad'), records what it got."""

    def __init__(self):
        self.lines: list[dict | str] = []
        self.server = None
        self.writers = []

    async def handle(self, reader, writer):
        self.writers.append(writer)
        while line := await reader.readline():
            text = line.decode().strip()
            self.lines.append(json.loads(text) if text.startswith("{") else text)
            writer.write(b"ERR bad polygon\n" if "bad" in text else f"OK {len(self.lines)}\n".encode())
            await writer.drain()
        writer.close()

    async def start(self, port=0):
        self.server = await asyncio.start_server(self.handle, "127.0.0.1", port)
        return self.server.sockets[0].getsockname()[1]

    async def stop(self):
        """Like a process exit: the listening socket and every open connection go away."""
        self.server.close()
        for writer in self.writers:
            writer.close()
        await self.server.wait_closed()


def test_boundary_line_is_one_json_line_in_the_protocol_shape():
    line = boundary_line(SQUARE, 7, time=100.0, uncertainty_m=250.0, source="ltc-fused")
    assert line.endswith(b"\n") and line.count(b"\n") == 1
    message = json.loads(line)
    assert message["type"] == "boundary" and message["horizon_h"] == 7 and message["crs"] == "EPSG:4326"
    assert message["polygon"][0] == [-88.4, 28.7] and message["source"] == "ltc-fused"


@pytest.mark.parametrize("bad,match", [([(0, 0), (1, 1)], "3 vertices"),
                                       ([(0, 0), (1, float("nan")), (1, 1)], "NaN")])
def test_boundary_line_rejects_degenerate_polygons(bad, match):
    with pytest.raises(ValueError, match=match):
        boundary_line(bad, 3)


def test_parse_reply():
    assert parse_reply(b"OK 12\n") == 12
    with pytest.raises(PushRejected, match="outside"):
        parse_reply(b"ERR outside the op area\n")
    with pytest.raises(ValueError, match="unexpected"):
        parse_reply(b"HELLO\n")


def test_push_reaches_listener_and_survives_its_restart():
    async def scenario():
        listener = Listener()
        port = await listener.start()
        pusher = BoundaryPusher("127.0.0.1", port, connect_timeout=5.0)
        assert await pusher.push(boundary_line(SQUARE, 3)) == 1
        with pytest.raises(PushRejected, match="bad polygon"):
            await pusher.push(b"pts={bad}\n")
        # pPathAssign restarts on the same port: the next push reconnects and is delivered
        await listener.stop()
        restarted = Listener()
        await restarted.start(port)
        assert await pusher.push(boundary_line(SQUARE, 15)) == 1
        assert restarted.lines[0]["horizon_h"] == 15
        await pusher.close()
        await restarted.stop()
        return listener.lines

    lines = asyncio.run(scenario())
    assert lines[0]["horizon_h"] == 3 and lines[1] == "pts={bad}"


def test_push_gives_up_with_a_clear_error_when_nobody_listens():
    async def scenario():
        listener = Listener()
        port = await listener.start()
        await listener.stop()
        await BoundaryPusher("127.0.0.1", port, connect_timeout=0.3).push(boundary_line(SQUARE, 3))

    with pytest.raises(PushUnreachable, match="127.0.0.1"):
        asyncio.run(scenario())
