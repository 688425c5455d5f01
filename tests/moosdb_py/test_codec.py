"""Every captured packet decodes to its recorded fields and re-encodes to the same bytes."""
from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import conformance_files, load_capture
from moosdb_py import codec
from moosdb_py.message import MOOSMsg

FIELDS = ("id", "type", "dtype", "src", "src_aux", "community", "key", "time", "dval", "dval2")


def _captured_packets():
    for path in conformance_files():
        for i, unit in enumerate(load_capture(path)["packets"]):
            yield pytest.param(unit, id=f"{path.stem}-{i}")


def _fields(msg: MOOSMsg) -> dict:
    return {"id": msg.id, "type": msg.msg_type, "dtype": msg.data_type, "src": msg.source,
            "src_aux": msg.source_aux, "community": msg.community, "key": msg.key, "time": msg.time,
            "dval": msg.double, "dval2": msg.double_aux}


def test_every_capture_is_read():
    assert len(conformance_files()) >= 19


@pytest.mark.parametrize("unit", list(_captured_packets()))
def test_capture_round_trip(unit):
    if unit["kind"] == "protocol":
        expected_ok = unit["text"].upper() == "ELKS CAN'T DANCE 2/8/10"
        slot = unit["text"].encode("latin-1").ljust(32, b"\0")
        assert codec.protocol_matches(slot) is expected_ok
        return
    if unit["kind"] != "packet":
        return  # trailing bytes of a stream that never formed a packet (scenario 11, conn 3)
    raw = bytes.fromhex(unit["hex"])
    decoded = unit["decoded"]
    msgs = codec.decode_packet(raw)
    assert len(msgs) == decoded["num_msgs"] and len(raw) == decoded["total_length"]
    for msg, want in zip(msgs, decoded["msgs"]):
        assert _fields(msg) == {k: want[k] for k in FIELDS}
        if want.get("sval_is_hex"):
            assert msg.binary == bytes.fromhex(want["sval"]) and msg.is_binary()
        else:
            assert msg.string == want["sval"]
        assert len(codec.encode_message(msg)) == want["length"]
    assert codec.encode_packet(msgs) == raw


def test_protocol_slot_is_name_padded_with_nul():
    assert codec.PROTOCOL_SLOT == b"ELKS CAN'T DANCE 2/8/10" + b"\0" * 9
    assert codec.protocol_matches(b"elks can't dance 2/8/10".ljust(32, b"\0"))
    assert not codec.protocol_matches(b"ELKS CAN'T DANCE 30/7/10".ljust(32, b"\0"))


def test_minimal_message_is_54_bytes():
    assert len(codec.encode_message(MOOSMsg())) == 54


def test_splices_equal_full_encodings():
    msg = MOOSMsg.notification("X", "hello", time=12.5, source="pub", source_aux="a", msg_id=3)
    packet = codec.encode_packet([MOOSMsg(), msg])
    where = codec.scan_packet(packet)[1]
    assert (where.msg_type, where.data_type, where.source, where.key) == ("N", "S", "pub", "X")
    spliced = codec.run_bytes(packet, where, codec.string_field(b"#1"))
    msg.community = "#1"
    assert spliced == codec.encode_message(msg)
    msg.id = -1
    assert codec.with_id(spliced, -1) == codec.encode_message(msg) and codec.message_id(codec.with_id(spliced, -1)) == -1


@pytest.mark.parametrize("mutate, reason", [
    (lambda b: b[:-1], "length field"),
    (lambda b: b[:9] + b"\x10\x00\x00\x00" + b[13:], "claims length"),
    (lambda b: b[:17] + b"Z" + b[18:], "unknown message type"),
    (lambda b: b[:18] + b"X" + b[19:], "unknown data type"),
    (lambda b: b[:4] + b"\x02\x00\x00\x00" + b[8:], "claims 2 messages"),
    (lambda b: b[:8] + b"\x01" + b[9:], "compressed"),
    (lambda b: b[:19] + b"\xff\xff\x00\x00" + b[23:], "source length"),
])
def test_malformed_packets_are_refused_with_reason(mutate, reason):
    good = codec.encode_packet([MOOSMsg.notification("K", 1.0, time=1.0, source="s")])
    bad = mutate(good)
    with pytest.raises(codec.CodecError, match=reason):
        codec.decode_packet(bad)


names = st.text(st.characters(min_codepoint=0, max_codepoint=255), max_size=12)
floats = st.floats(allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(msg_type=st.sampled_from(sorted("NRU*/CQTWKi.")), data_type=st.sampled_from("DSB"), key=names,
       source=names, aux=names, community=names, time=floats, dval=floats, dval2=floats,
       payload=st.binary(max_size=40), msg_id=st.integers(-2**31, 2**31 - 1))
def test_any_message_round_trips(msg_type, data_type, key, source, aux, community, time, dval, dval2,
                                 payload, msg_id):
    msg = MOOSMsg(msg_type, data_type, key, dval, source=source, source_aux=aux, community=community,
                  time=time, id=msg_id, double_aux=dval2)
    if data_type == "B":
        msg.binary = payload
    else:
        msg.string = payload.decode("latin-1")
    packet = codec.encode_packet([msg, msg])
    assert codec.decode_packet(packet) == [msg, msg]


def test_value_types():
    assert MOOSMsg.notification("A", 2, time=0).value == 2.0
    assert MOOSMsg.notification("A", "s", time=0).is_string()
    assert MOOSMsg.notification("A", b"\0", time=0).value == b"\0"
    with pytest.raises(TypeError, match="A"):
        MOOSMsg.notification("A", None, time=0)


def _messages(runs):
    return [(run, s, e) for run in runs for s, e in zip(run.bounds, run.bounds[1:])]


@settings(max_examples=60, deadline=None)
@given(picks=st.lists(st.tuples(st.sampled_from(["X", "NAV_X", "Y"]), st.sampled_from(["a", "bb"]),
                                st.sampled_from(["", "#1"]), st.one_of(floats, names)), min_size=1, max_size=12),
       repeat=st.integers(1, 12))
def test_scan_packet_agrees_with_decode(picks, repeat):
    """Runs of same-prefix messages take the fast paths; they must locate exactly what decoding finds,
    and forward exactly the full encodings with the community filled in."""
    msgs = []
    for i, (key, source, community, value) in enumerate(p for p in picks for _ in range(repeat)):
        msg = MOOSMsg.notification(key, value, time=float(i), source=source, msg_id=i)
        msg.community = community
        msgs.append(msg)
    packet = codec.encode_packet(msgs)
    runs = codec.scan_packet(packet)
    found = _messages(runs)
    assert [(r.msg_type, r.data_type, r.source, r.key, r.community_len) for r, _, _ in found] == \
        [(m.msg_type, m.data_type, m.source, m.key, len(m.community)) for m in msgs]
    assert [codec.decode_message(packet[s:e])[0] for _, s, e in found] == msgs
    assert all(packet[s + r.community_rel:s + r.community_rel + 4] == len(m.community).to_bytes(4, "little")
               for (r, s, _), m in zip(found, msgs))
    forwarded = b"".join(codec.run_bytes(packet, run, codec.string_field(b"#7")) for run in runs)
    for msg in msgs:
        msg.community = msg.community or "#7"
    assert forwarded == b"".join(map(codec.encode_message, msgs))


def test_long_runs_are_one_run_each():
    msgs = ([MOOSMsg.notification("NAV_X", float(i), time=1.0, source="sim", msg_id=i) for i in range(300)]
            + [MOOSMsg.notification("NAV_X", "s" * (i % 3), time=1.0, source="sim") for i in range(5)]
            + [MOOSMsg.notification(k, 1.0, time=1.0, source="sim") for k in ["A", "A", "B", "B"] * 20])
    runs = codec.scan_packet(codec.encode_packet(msgs))
    assert [r.count for r in runs[:4]] == [300, 5, 2, 2] and len(runs) == 42
    assert isinstance(runs[0].bounds, range)


@pytest.mark.parametrize("where", [5, 150, 299])
def test_scan_packet_fast_path_still_checks_lengths(where):
    same = [MOOSMsg.notification("X", "abc", time=1.0, source="p") for _ in range(300)]
    size = len(codec.encode_message(same[0]))
    packet = bytearray(codec.encode_packet(same))
    packet[9 + (where + 1) * size - 7] = 9       # that message's sval length: 3 -> 9
    with pytest.raises(codec.CodecError):
        codec.scan_packet(bytes(packet))


@settings(max_examples=60, deadline=None)
@given(packets=st.lists(st.lists(st.tuples(st.sampled_from(["X", "NAV_X", "Y", "Z"]), st.one_of(floats, names)),
                                 min_size=1, max_size=8), min_size=1, max_size=6),
       corrupt=st.one_of(st.none(), st.integers(0, 10_000)))
def test_packet_scanner_agrees_with_scan_packet(packets, corrupt):
    """A client's packets again and again with one layout (values change, layout does not), and
    sometimes a byte changed: the remembered layout must never let a different packet through."""
    scanner = codec.PacketScanner()
    for picks in packets + packets[-1:] * 2:
        for shift in (0.0, 1.0, 2.0):                  # other doubles, same layout
            packet = bytearray(codec.encode_packet([MOOSMsg.notification(k, v + shift if isinstance(v, float) else v,
                                                                         time=shift, source="app") for k, v in picks]))
            assert _messages(scanner.scan(bytes(packet))) == _messages(codec.scan_packet(bytes(packet)))
    if corrupt is not None:
        packet[corrupt % len(packet)] ^= 0x41
        try:
            expected = _messages(codec.scan_packet(bytes(packet)))
        except codec.CodecError:
            with pytest.raises(codec.CodecError):
                scanner.scan(bytes(packet))
        else:
            assert _messages(scanner.scan(bytes(packet))) == expected


def test_packet_scanner_reuses_a_layout_only_for_the_same_layout():
    scanner = codec.PacketScanner()
    def packet(key, value):
        return codec.encode_packet([MOOSMsg.notification("NAV_X", 1.0, time=1.0, source="sim"),
                                    MOOSMsg.notification(key, value, time=2.0, source="sim")])
    for value in (1.0, 2.0, 3.0):
        runs = scanner.scan(packet("NAV_Y", value))
        assert [r.key for r in runs] == ["NAV_X", "NAV_Y"]
    assert [r.key for r in scanner.scan(packet("NAV_Z", 4.0))] == ["NAV_X", "NAV_Z"]     # same size, other key
    bad = bytearray(packet("NAV_Y", 5.0))
    bad[-4] = 1                                                                        # sval length 0 -> 1
    with pytest.raises(codec.CodecError):
        scanner.scan(bytes(bad))
