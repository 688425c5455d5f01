"""The MOOS V10 wire format, sans I/O: bytes in, messages out, and back.

Layouts follow ../shared/spec/moos-wire-protocol.md §1-§4: little-endian, a message is
length|id|type|dtype|src|src_aux|community|key|time|dval|dval2|sval, a packet is
length|count|compression-flag|messages, and a connection starts with a 32-byte protocol slot.
The C++ reader silently stops at the first bad message; this one raises `CodecError` instead,
so a server can drop the offending client with the reason.
"""
from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import NamedTuple

from .message import BINARY, MSG_TYPES, WIRE_DATA_TYPES, MOOSMsg

PROTOCOL_NAME = b"ELKS CAN'T DANCE 2/8/10"
PROTOCOL_SLOT_SIZE = 32
PROTOCOL_SLOT = PROTOCOL_NAME.ljust(PROTOCOL_SLOT_SIZE, b"\0")
PACKET_HEADER_SIZE = 9
MIN_MESSAGE_SIZE = 54
DEFAULT_MAX_PACKET = 64 * 1024 * 1024

_INT = struct.Struct("<i")
_MSG_HEAD = struct.Struct("<iicc")
_DOUBLES = struct.Struct("<ddd")
_PKT_HEAD = struct.Struct("<iiB")
_EMPTY_STR = _INT.pack(0)


class CodecError(ValueError):
    """Bytes that are not a valid MOOS message or packet."""


def _text(value: str) -> bytes:
    """latin-1 keeps every byte value; text outside it goes out as UTF-8 rather than failing."""
    try:
        return value.encode("latin-1")
    except UnicodeEncodeError:
        return value.encode("utf-8")


def string_field(data: bytes) -> bytes:
    """A string as it sits in a message: int32 length, then the bytes."""
    return _INT.pack(len(data)) + data if data else _EMPTY_STR


def encode_message(msg: MOOSMsg) -> bytes:
    src, aux, comm, key = _text(msg.source), _text(msg.source_aux), _text(msg.community), _text(msg.key)
    sval = msg.binary if msg.data_type == BINARY else _text(msg.string)
    length = MIN_MESSAGE_SIZE + len(src) + len(aux) + len(comm) + len(key) + len(sval)
    return b"".join((
        _MSG_HEAD.pack(length, msg.id, msg.msg_type.encode("latin-1"), msg.data_type.encode("latin-1")),
        string_field(src), string_field(aux), string_field(comm), string_field(key),
        _DOUBLES.pack(msg.time, msg.double, msg.double_aux),
        string_field(sval),
    ))


class WireMsg(NamedTuple):
    """Where a message sits in a buffer and what a router needs of it, without decoding the rest."""

    start: int
    end: int
    msg_type: str
    data_type: str
    source: str
    key: str
    community_at: int      # offset of the community's length field
    community_len: int


def _string_at(buf: bytes, p: int, limit: int, name: str, pos: int) -> tuple[int, int]:
    """Start and length of the string field whose length prefix is at `p`."""
    (n,) = _INT.unpack_from(buf, p)
    if n < 0 or p + 4 + n > limit:
        raise CodecError(f"{name} length {n} runs past the message at byte {pos}")
    return p + 4, n


def _layout(buf: bytes, pos: int) -> tuple:
    """Validate the message at `pos`.

    Returns (end, id, type, dtype, then start and length of source, source aux, community and key,
    then the offset of the three doubles).
    """
    avail = len(buf)
    if avail - pos < MIN_MESSAGE_SIZE:
        raise CodecError(f"truncated message at byte {pos}: {avail - pos} bytes left, a message needs >= 54")
    length, msg_id, mtype, dtype = _MSG_HEAD.unpack_from(buf, pos)
    end = pos + length
    if length < MIN_MESSAGE_SIZE or end > avail:
        raise CodecError(f"message at byte {pos} claims length {length} but {avail - pos} bytes remain")
    msg_type, data_type = chr(mtype[0]), chr(dtype[0])
    if msg_type not in MSG_TYPES:
        raise CodecError(f"unknown message type {msg_type!r} at byte {pos}")
    if data_type not in WIRE_DATA_TYPES:
        raise CodecError(f"unknown data type {data_type!r} at byte {pos}")
    limit = end - 28          # the three doubles and the sval length follow the strings
    s0, n0 = _string_at(buf, pos + 10, limit, "source", pos)
    s1, n1 = _string_at(buf, s0 + n0, limit, "source aux", pos)
    s2, n2 = _string_at(buf, s1 + n1, limit, "community", pos)
    s3, n3 = _string_at(buf, s2 + n2, limit, "key", pos)
    p = s3 + n3
    (n,) = _INT.unpack_from(buf, p + 24)
    if n < 0 or p + 28 + n != end:
        raise CodecError(f"message at byte {pos}: length field {length} disagrees with its fields "
                         f"({p + 28 + max(n, 0) - pos} bytes)")
    return end, msg_id, msg_type, data_type, s0, n0, s1, n1, s2, n2, s3, n3, p


def scan_message(buf: bytes, pos: int = 0) -> WireMsg:
    """Check the message at `pos` and pick out type, source and key (the DB's notify fast path)."""
    end, _, msg_type, data_type, s0, n0, _, _, s2, n2, s3, n3, _ = _layout(buf, pos)
    return WireMsg(pos, end, msg_type, data_type, buf[s0:s0 + n0].decode("latin-1"),
                   buf[s3:s3 + n3].decode("latin-1"), s2 - 4, n2)


def decode_message(buf: bytes, pos: int = 0) -> tuple[MOOSMsg, int]:
    """Decode the message starting at `pos`; return it and the offset just past it."""
    end, msg_id, msg_type, data_type, s0, n0, s1, n1, s2, n2, s3, n3, p = _layout(buf, pos)
    time, dval, dval2 = _DOUBLES.unpack_from(buf, p)
    msg = MOOSMsg(msg_type, data_type, buf[s3:s3 + n3].decode("latin-1"), dval, "", b"",
                  buf[s0:s0 + n0].decode("latin-1"), buf[s1:s1 + n1].decode("latin-1"),
                  buf[s2:s2 + n2].decode("latin-1"), time, msg_id, dval2)
    if data_type == BINARY:
        msg.binary = bytes(buf[p + 28:end])
    else:
        msg.string = buf[p + 28:end].decode("latin-1")
    return msg, end


def fill_community(buf: bytes, where: WireMsg, community_field: bytes) -> bytes:
    """The message (community empty) with `string_field(community)` put in: a splice, the rest untouched."""
    at, start, end = where.community_at, where.start, where.end
    return _INT.pack(end - start + len(community_field) - 4) + buf[start + 4:at] + community_field + buf[at + 4:end]


def with_id(wire: bytes, msg_id: int) -> bytes:
    """The same message with another id (the DB sends current values with id -1)."""
    return wire[:4] + _INT.pack(msg_id) + wire[8:]


def message_id(wire: bytes) -> int:
    return _INT.unpack_from(wire, 4)[0]


def pack_packet(wires: Iterable[bytes]) -> bytes:
    """A packet of already-encoded messages (how the DB forwards mail untouched)."""
    wires = wires if isinstance(wires, list) else list(wires)
    body = b"".join(wires)
    return _PKT_HEAD.pack(PACKET_HEADER_SIZE + len(body), len(wires), 0) + body


def encode_packet(msgs: Iterable[MOOSMsg]) -> bytes:
    return pack_packet([encode_message(m) for m in msgs])


def _packet_count(packet: bytes) -> int:
    if len(packet) < PACKET_HEADER_SIZE:
        raise CodecError(f"packet of {len(packet)} bytes is shorter than its 9-byte header")
    total, count, compressed = _PKT_HEAD.unpack_from(packet, 0)
    if total != len(packet):
        raise CodecError(f"packet length field {total} but {len(packet)} bytes given")
    if compressed:
        raise CodecError(f"compressed packets are not supported (flag {compressed})")
    if count < 0 or count * MIN_MESSAGE_SIZE > total - PACKET_HEADER_SIZE:
        raise CodecError(f"packet claims {count} messages in {total} bytes")
    return count


def _check_end(packet: bytes, pos: int, count: int) -> None:
    if pos != len(packet):
        raise CodecError(f"packet has {len(packet) - pos} stray bytes after its {count} messages")


def decode_packet(packet: bytes) -> list[MOOSMsg]:
    count = _packet_count(packet)
    msgs = []
    pos = PACKET_HEADER_SIZE
    for _ in range(count):
        msg, pos = decode_message(packet, pos)
        msgs.append(msg)
    _check_end(packet, pos, count)
    return msgs


def scan_packet(packet: bytes) -> list[WireMsg]:
    """Validate a whole packet and locate its messages without decoding them.

    Busy publishers send runs of messages whose bytes from the type letters to the end of the key
    are identical (same variable, same source); such a message is recognised by that prefix and
    only its lengths are checked, which is what makes a DB's fan-in fast.
    """
    count = _packet_count(packet)
    found = []
    pos = PACKET_HEADER_SIZE
    total = len(packet)
    unpack = _INT.unpack_from
    prefix = b""          # bytes 8..end-of-key of the last fully checked message
    for _ in range(count):
        if prefix and packet.startswith(prefix, pos + 8):
            (length,) = unpack(packet, pos)
            end = pos + length
            p = pos + 8 + len(prefix)            # the three doubles
            if end <= total and p + 28 <= end and unpack(packet, p + 24)[0] == end - p - 28:
                found.append(WireMsg(pos, end, last.msg_type, last.data_type, last.source, last.key,
                                     pos + community_rel, last.community_len))
                pos = end
                continue
        last = scan_message(packet, pos)
        community_rel = last.community_at - pos
        key_end = last.community_at + 8 + last.community_len + len(last.key)
        prefix = packet[pos + 8:key_end]
        found.append(last)
        pos = last.end
    _check_end(packet, pos, count)
    return found


def protocol_matches(slot: bytes) -> bool:
    """The DB's check of the 32-byte slot: C-string compare, case-insensitive."""
    return slot.split(b"\0", 1)[0].upper() == PROTOCOL_NAME.upper()


class FramingError(ValueError):
    """A packet length in the stream that cannot be right (negative, too small, over the cap)."""


class StreamFramer:
    """Split a TCP byte stream into protocol slot and packets, however the bytes were chunked.

    `feed` buffers bytes; `next_unit` returns the next complete unit or None (h11 style, so the
    caller can stop mid-buffer, e.g. after a bad protocol slot). A length header outside
    [9, max_packet] raises `FramingError` as soon as its 4 bytes are in, before any allocation.
    """

    def __init__(self, *, protocol_slot: bool = False, max_packet: int = DEFAULT_MAX_PACKET):
        self._buf = bytearray()
        self._pos = 0
        self._need_slot = protocol_slot
        self.max_packet = max_packet

    @property
    def buffered(self) -> int:
        return len(self._buf) - self._pos

    def feed(self, data: bytes) -> None:
        if self._pos:
            del self._buf[:self._pos]
            self._pos = 0
        self._buf += data

    def next_unit(self) -> bytes | None:
        buf, pos = self._buf, self._pos
        avail = len(buf) - pos
        if self._need_slot:
            if avail < PROTOCOL_SLOT_SIZE:
                return None
            self._need_slot = False
            self._pos = pos + PROTOCOL_SLOT_SIZE
            return bytes(buf[pos:self._pos])
        if avail < 4:
            return None
        (total,) = _INT.unpack_from(buf, pos)
        if total < PACKET_HEADER_SIZE or total > self.max_packet:
            raise FramingError(f"packet length {total} outside [{PACKET_HEADER_SIZE}, {self.max_packet}]")
        if avail < total:
            return None
        self._pos = pos + total
        return bytes(buf[pos:self._pos])

    def units(self, data: bytes) -> list[bytes]:
        """Feed `data` and return every unit it completes."""
        self.feed(data)
        out = []
        while (unit := self.next_unit()) is not None:
            out.append(unit)
        return out
