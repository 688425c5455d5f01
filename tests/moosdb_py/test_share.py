"""pShare's pure parts: the datagram codec, routes, config lines, PSHARE_CMD and the routing table."""
from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moosdb_py.message import MOOSMsg
from moosdb_py.share import (
    MAX_DATAGRAM,
    DatagramTooLarge,
    MalformedDatagram,
    OutputSpec,
    Route,
    ShareConfigError,
    ShareTable,
    decode_datagram,
    encode_datagram,
    parse_command,
    parse_input,
    parse_output,
    parse_route,
)


def spec_layout(msg_id, dtype, src, aux, community, key, time, dval, dval2, sval: bytes) -> bytes:
    """docs/spec/field-apps.md 4.4, written out field by field."""
    def s(b: bytes) -> bytes:
        return struct.pack("<i", len(b)) + b
    body = (struct.pack("<i", msg_id) + b"N" + dtype + s(src) + s(aux) + s(community) + s(key)
            + struct.pack("<ddd", time, dval, dval2) + s(sval))
    return struct.pack("<i", len(body) + 4) + body


def test_datagram_bytes_follow_the_spec_layout():
    msg = MOOSMsg.notification("DEPLOY_ALL", "true", time=1708012345.25, source="uPokeDB", source_aux="x", msg_id=7)
    wire = encode_datagram(msg, "DEPLOY", "shoreside")
    assert wire == spec_layout(7, b"S", b"uPokeDB", b"x", b"shoreside", b"DEPLOY", 1708012345.25, -1.0, -1.0, b"true")
    dbl = MOOSMsg.notification("NAV_X", 12.5, time=3.0, source="uSimMarine")
    assert encode_datagram(dbl, "NAV_X", "abe") == spec_layout(-1, b"D", b"uSimMarine", b"", b"abe", b"NAV_X",
                                                                3.0, 12.5, -1.0, b"")


names = st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=20)
values = st.one_of(st.floats(allow_nan=False), st.text(alphabet=st.characters(max_codepoint=255), max_size=200),
                   st.binary(max_size=200))


@settings(max_examples=80)
@given(names, names, values, names, st.floats(allow_nan=False), names)
def test_datagram_round_trip_keeps_source_community_time(key, dest, value, source, time, community):
    msg = MOOSMsg.notification(key, value, time=time, source=source, source_aux="aux")
    got = decode_datagram(encode_datagram(msg, dest, community))
    assert (got.key, got.value, got.source, got.source_aux, got.community, got.time) == \
        (dest, value, source, "aux", community, time)


@settings(max_examples=150)
@given(st.binary(max_size=120))
def test_random_bytes_are_rejected_cleanly(data):
    try:
        msg = decode_datagram(data)
    except MalformedDatagram:
        return
    assert msg.key  # the rare random input that is a real notify decodes to one


def test_malformed_datagrams_name_the_problem():
    good = encode_datagram(MOOSMsg.notification("X", 1.0, time=0.0), "X", "c")
    with pytest.raises(MalformedDatagram, match="stray bytes"):
        decode_datagram(good + b"\0")
    with pytest.raises(MalformedDatagram, match="not a MOOS message"):
        decode_datagram(good[:-3])
    register = bytearray(good)
    register[8] = ord("R")
    with pytest.raises(MalformedDatagram, match="only notifies"):
        decode_datagram(bytes(register))
    with pytest.raises(MalformedDatagram, match="without a variable"):
        decode_datagram(encode_datagram(MOOSMsg.notification("X", 1.0, time=0.0), "", "c"))


def test_oversize_value_is_a_clear_error():
    big = MOOSMsg.notification("PICTURE", b"\x01" * MAX_DATAGRAM, time=0.0, source="cam")
    with pytest.raises(DatagramTooLarge, match=r"PICTURE -> PICTURE: \d+ bytes"):
        encode_datagram(big, "PICTURE", "abe")
    fits = MOOSMsg.notification("P", b"\x01" * (MAX_DATAGRAM - 60), time=0.0)
    assert len(encode_datagram(fits, "P", "ab")) <= MAX_DATAGRAM


def test_routes():
    assert parse_route("localhost:9201") == Route("localhost", 9201)
    assert parse_route("multicast_8") == Route("224.1.1.11", 24468, 8)
    assert str(parse_route("multicast_8", "224.1.1.12", 9061)) == "224.1.1.12:9069:multicast_8"
    for bad in ("localhost", "localhost:x", ":9000", "host:70000", "multicast_256", "multicast_x"):
        with pytest.raises(ShareConfigError):
            parse_route(bad)


def test_config_lines_and_commands():
    warnings: list[str] = []
    assert parse_output("src_name = X, dest_name = Y, route = 10.0.0.2:9000 & multicast_8, frequency = 2",
                        warnings) == [OutputSpec("X", "Y", ("10.0.0.2:9000", "multicast_8"), 2.0)]
    assert parse_output("src_name=P,route=localhost:9200", warnings) == [OutputSpec("P", "P", ("localhost:9200",))]
    assert parse_output("X->Y:165.45.3.61:9000@0.5 & multicast_8", warnings) == [
        OutputSpec("X", "Y", ("165.45.3.61:9000",), 0.5), OutputSpec("X", "X", ("multicast_8",))]
    assert parse_input("route = localhost:9201 & multicast_9", warnings) == ("localhost:9201", "multicast_9")
    assert not warnings
    assert parse_input("route=localhost:9201,white_list=DEPLOY", warnings) == ("localhost:9201",)
    assert "white_list" in warnings[0]
    assert parse_command("cmd=output,src_name=A,dest_name=B,route=localhost:1", []) == \
        ([OutputSpec("A", "B", ("localhost:1",))], ())
    assert parse_command("cmd=input,route=localhost:9205", []) == ([], ("localhost:9205",))
    for bad, match in [("cmd=delete,route=x:1", "output or input"), ("cmd=output,route=x:1", "src_name"),
                       ("cmd=output,src_name=A", "neither"), ("cmd=output,src_name=A,route=", "route is required"),
                       ("cmd=output,src_name=A,route=x:1,frequency=fast", "frequency"), ("cmd=input", "route")]:
        with pytest.raises(ShareConfigError, match=match):
            parse_command(bad, [])


def msg(key, value="v", source="app", time=0.0):
    return MOOSMsg.notification(key, value, time=time, source=source)


def test_table_forwards_renames_and_dedups():
    table = ShareTable()
    spec = OutputSpec("NODE_REPORT_LOCAL", "NODE_REPORT", ("localhost:9200",))
    assert [s.var for s in table.add_output(spec)] == ["NODE_REPORT_LOCAL"]
    assert table.add_output(spec) == []  # the same share again changes nothing
    table.add_output(OutputSpec("NODE_REPORT_LOCAL", "NR", ("localhost:9300",)))
    out = table.forward(msg("NODE_REPORT_LOCAL"), 1.0)
    assert [(o.dest, str(o.route)) for o in out] == [("NODE_REPORT", "localhost:9200"), ("NR", "localhost:9300")]
    assert table.forward(msg("OTHER"), 1.0) == []
    assert table.output_summary() == "NODE_REPORT_LOCAL->NODE_REPORT:localhost:9200 & NR:localhost:9300"
    assert table.add_input("localhost:9201") == Route("localhost", 9201)
    assert table.add_input("localhost:9201") is None
    table.add_input("multicast_3")
    assert table.input_summary() == "localhost:9201,224.1.1.11:24463:multicast_3"
    assert table.is_shared("NODE_REPORT_LOCAL") and not table.is_shared("NODE_REPORT")


def test_frequency_limit_per_route():
    table = ShareTable()
    table.add_output(OutputSpec("X", "X", ("h:1",), 2.0))
    table.add_output(OutputSpec("X", "Y", ("h:2",)))
    sent = [len(table.forward(msg("X"), t)) for t in (0.0, 0.1, 0.3, 0.5, 0.6)]
    assert sent == [2, 1, 1, 2, 1]


def test_wildcard_outputs():
    table = ShareTable()
    subs = table.add_output(OutputSpec("NAV_*", "V1_", ("h:1",)))
    assert [(s.var, s.app_pattern) for s in subs] == [("NAV_*", "*")]
    table.add_output(OutputSpec("*_ABE", "^", ("h:2",)))
    table.add_output(OutputSpec("DESIRED_*:pHelm*", "DESIRED_*", ("h:3",)))
    assert [o.dest for o in table.forward(msg("NAV_X"), 0.0)] == ["V1_NAV_X"]
    assert [o.dest for o in table.forward(msg("DEPLOY_ABE"), 0.0)] == ["DEPLOY"]
    assert table.forward(msg("DESIRED_SPEED", source="pMarinePID"), 0.0) == []
    assert [o.dest for o in table.forward(msg("DESIRED_HEADING", source="pHelmIvP"), 0.0)] == ["DESIRED_HEADING"]
    assert table.is_shared("NAV_Y") and not table.is_shared("NAV")
    assert "NAV_X->V1_NAV_X:h:1" in table.output_summary()
    assert [(s.var, s.app_pattern) for s in table.subscriptions()][-1] == ("DESIRED_*", "pHelm*")
