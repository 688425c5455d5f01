"""The framer splits each captured byte stream into exactly the captured units, however chunked."""
from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import conformance_files, load_capture
from moosdb_py import codec


def _streams():
    for path in conformance_files():
        cap = load_capture(path)
        for conn in sorted({c["conn"] for c in cap["chunks"]}):
            for direction in ("c2s", "s2c"):
                chunks = [bytes.fromhex(c["hex"]) for c in cap["chunks"]
                          if c["conn"] == conn and c.get("dir") == direction]
                units = [u for u in cap["packets"] if u.get("conn") == conn and u.get("dir") == direction]
                if chunks:
                    yield pytest.param(chunks, units, direction, id=f"{path.stem}-{conn}-{direction}")


def _expected(unit) -> bytes:
    if unit["kind"] == "protocol":
        return unit["text"].encode("latin-1").ljust(32, b"\0")
    return bytes.fromhex(unit["hex"])


@pytest.mark.parametrize("chunks, units", [p.values[:2] for p in _streams()])
def test_captured_streams_split_into_captured_units(chunks, units):
    framer = codec.StreamFramer(protocol_slot=units[0]["kind"] == "protocol")
    stream = b"".join(chunks)
    complete = [u for u in units if u["kind"] != "trailing_unparsed"]
    if len(complete) < len(units):
        # scenario 11, conn 3: no protocol slot, so what follows the first 32 bytes is garbage
        with pytest.raises(codec.FramingError):
            framer.units(stream)
        return
    got = [u for chunk in chunks for u in framer.units(chunk)]
    assert got == [_expected(u) for u in complete]
    assert framer.buffered == 0


@settings(max_examples=60, deadline=None)
@given(cuts=st.lists(st.integers(min_value=0, max_value=2000), max_size=30))
def test_any_chunking_gives_the_same_packets(cuts):
    cap = load_capture(conformance_files()[6])
    stream = b"".join(bytes.fromhex(c["hex"]) for c in cap["chunks"] if c["conn"] == 2 and c.get("dir") == "c2s")
    whole = codec.StreamFramer(protocol_slot=True).units(stream)
    framer = codec.StreamFramer(protocol_slot=True)
    edges = sorted({0, len(stream), *(c % (len(stream) + 1) for c in cuts)})
    got = [u for a, b in zip(edges, edges[1:]) for u in framer.units(stream[a:b])]
    assert got == whole and len(whole) > 3


@pytest.mark.parametrize("length", [-1, 0, 8, 1_000_001, 2**31 - 1])
def test_absurd_lengths_are_refused_before_buffering(length):
    framer = codec.StreamFramer(max_packet=1_000_000)
    with pytest.raises(codec.FramingError, match=str(length)):
        framer.units(length.to_bytes(4, "little", signed=True))
