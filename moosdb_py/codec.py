"""The MOOS V10 wire format, sans I/O: bytes in, messages out, and back.

Layouts follow docs/spec/moos-wire-protocol.md §1-§4: little-endian, a message is
length|id|type|dtype|src|src_aux|community|key|time|dval|dval2|sval, a packet is
length|count|compression-flag|messages, and a connection starts with a 32-byte protocol slot.
The C++ reader silently stops at the first bad message; this one raises `CodecError` instead,
so a server can drop the offending client with the reason.
"""
from __future__ import annotations

import functools
import struct
from collections.abc import Iterable, Sequence
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


def as_on_the_wire(msg: MOOSMsg) -> None:
    """Make the message's text what a reader decodes from `encode_message` of it (text outside latin-1
    arrives as its UTF-8 bytes read as latin-1): how the in-process path gives the mail a socket would."""
    if (msg.key + msg.source + msg.source_aux + msg.string).isascii():
        return
    for name in ("key", "source", "source_aux", "string"):
        value = getattr(msg, name)
        if not value.isascii():
            setattr(msg, name, _text(value).decode("latin-1"))


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


class WireRun(NamedTuple):
    """Consecutive messages alike from their type letters to the end of their key (one variable written
    by one source, as a busy publisher sends them): located and checked, not decoded."""

    msg_type: str
    data_type: str
    source: str
    key: str
    community_len: int
    community_rel: int          # offset of the community's length field from each message's start
    key_end: int                # offset of the end of the key (where the three doubles begin)
    bounds: Sequence[int]       # message i is buf[bounds[i]:bounds[i + 1]]; a range when all are one size

    @property
    def start(self) -> int:
        return self.bounds[0]

    @property
    def count(self) -> int:
        return len(self.bounds) - 1


_STRING_FIELDS = ("source", "source aux", "community", "key")


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
    e = pos + 10
    found = []
    for name in _STRING_FIELDS:
        (n,) = _INT.unpack_from(buf, e)
        e += 4 + n
        if n < 0 or e > limit:
            raise CodecError(f"{name} length {n} runs past the message at byte {pos}")
        found += (e - n, n)
    s0, n0, s1, n1, s2, n2, s3, n3 = found
    p = e
    (n,) = _INT.unpack_from(buf, p + 24)
    if n < 0 or p + 28 + n != end:
        raise CodecError(f"message at byte {pos}: length field {length} disagrees with its fields "
                         f"({p + 28 + max(n, 0) - pos} bytes)")
    return end, msg_id, msg_type, data_type, s0, n0, s1, n1, s2, n2, s3, n3, p


_new_tuple = tuple.__new__     # builds a WireRun without namedtuple's Python-level __new__ or _replace (hot path)


def scan_message(buf: bytes, pos: int = 0) -> WireRun:
    """Check the message at `pos` and pick out type, source and key (the DB's notify fast path)."""
    end, _, msg_type, data_type, s0, n0, _, _, s2, n2, s3, n3, p = _layout(buf, pos)
    return _new_tuple(WireRun, (msg_type, data_type, buf[s0:s0 + n0].decode("latin-1"),
                                buf[s3:s3 + n3].decode("latin-1"), n2, s2 - 4 - pos, p - pos, (pos, end)))


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


@functools.lru_cache(maxsize=256)
def _row_struct(key_end: int, size: int) -> struct.Struct:
    """A message of this layout as (length field, type letters..key, sval length field)."""
    return struct.Struct(f"<4s4x{key_end - 8}s24x4s{size - key_end - 28}x")


@functools.lru_cache(maxsize=256)
def _split_struct(key_end: int, size: int) -> struct.Struct:
    """A message of this layout as (id, doubles and sval): the parts a community splice keeps."""
    return struct.Struct(f"<4x4s{key_end - 8}x{size - key_end}s")


def run_bytes(buf: bytes, run: WireRun, community_field: bytes) -> bytes:
    """The run's messages back to back as the DB forwards them: the bytes that came in, with an empty
    community replaced by `community_field` (`string_field(community)`)."""
    bounds = run.bounds
    start = bounds[0]
    if run.community_len:
        return buf[start:bounds[-1]]
    at, key_end = run.community_rel, run.key_end
    if len(bounds) == 2:
        end = bounds[1]
        return _INT.pack(end - start + len(community_field) - 4) + buf[start + 4:start + at] + community_field \
            + buf[start + at + 4:end]
    head = buf[start + 8:start + at] + community_field + buf[start + at + 4:start + key_end]
    grow = len(community_field) - 4
    pack = _INT.pack
    if isinstance(bounds, range):          # all one size: split every message in one C call
        size, k = bounds.step, len(bounds) - 1
        ids, tails = zip(*_split_struct(key_end, size).iter_unpack(memoryview(buf)[start:bounds[-1]]))
        out = [pack(size + grow), None, head, None] * k
        out[1::4], out[3::4] = ids, tails
        return b"".join(out)
    out = []
    for s, e in zip(bounds, bounds[1:]):
        out += (pack(e - s + grow), buf[s + 4:s + 8], head, buf[s + key_end:e])
    return b"".join(out)


def with_id(wire: bytes, msg_id: int) -> bytes:
    """The same message with another id (the DB sends current values with id -1)."""
    return wire[:4] + _INT.pack(msg_id) + wire[8:]


def message_id(wire: bytes) -> int:
    return _INT.unpack_from(wire, 4)[0]


def pack_packet(chunks: Iterable[bytes], count: int | None = None) -> bytes:
    """A packet of already-encoded messages (how the DB forwards mail untouched); `count` is the number
    of messages when a chunk holds several back to back."""
    chunks = chunks if isinstance(chunks, list) else list(chunks)
    size = PACKET_HEADER_SIZE + sum(map(len, chunks))
    return b"".join([_PKT_HEAD.pack(size, len(chunks) if count is None else count, 0), *chunks])


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


def decode_run(buf: bytes, count: int, pos: int = 0) -> tuple[list[MOOSMsg], int]:
    """`count` messages back to back in `buf` from `pos` (a packet's body, a run of mail the DB holds),
    and the offset just past them."""
    msgs = []
    for _ in range(count):
        msg, pos = decode_message(buf, pos)
        msgs.append(msg)
    return msgs, pos


def decode_packet(packet: bytes) -> list[MOOSMsg]:
    count = _packet_count(packet)
    msgs, end = decode_run(packet, count, PACKET_HEADER_SIZE)
    _check_end(packet, end, count)
    return msgs


def scan_packet(packet: bytes) -> list[WireRun]:
    """Validate a whole packet and locate its messages, grouped in runs, without decoding them.

    Busy publishers send runs of messages whose bytes from the type letters to the end of the key
    are identical (same variable, same source); after the first, such a message is recognised by
    that prefix and only its lengths are checked, and a stretch of them of one size is checked in a
    single struct pass. This is what makes a DB's fan-in fast.
    """
    count = _packet_count(packet)
    runs = []
    pos = PACKET_HEADER_SIZE
    left = count
    while left:
        run = scan_message(packet, pos)
        left -= 1
        start, pos = run.bounds
        if left and packet.startswith(packet[start + 8:start + run.key_end], pos + 8):
            run = _extend(packet, run, left)
            left -= len(run.bounds) - 2
            pos = run.bounds[-1]
        runs.append(run)
    _check_end(packet, pos, count)
    return runs


def _extend(packet: bytes, run: WireRun, left: int) -> WireRun:
    """`run` (one checked message) grown by up to `left` following messages with its prefix."""
    start, end = run.bounds
    key_end = run.key_end
    prefix = packet[start + 8:start + key_end]
    size = end - start
    rows = 1 + _same_rows(packet, start, size, key_end, min(left, (len(packet) - end) // size))
    bounds = range(start, start + rows * size + 1, size) if rows > 1 else [start, end]
    left -= rows - 1
    total = len(packet)
    unpack = _INT.unpack_from
    pos = bounds[-1]
    while left and packet.startswith(prefix, pos + 8):      # same prefix, other sizes (strings)
        (length,) = unpack(packet, pos)
        end = pos + length
        p = pos + key_end
        if end > total or p + 28 > end or unpack(packet, p + 24)[0] != end - p - 28:
            break                         # not a good message: scan_message will say why
        if isinstance(bounds, range):
            bounds = list(bounds)
        bounds.append(end)
        pos = end
        left -= 1
    return _new_tuple(WireRun, (*run[:-1], bounds))


def _same_rows(packet: bytes, start: int, size: int, key_end: int, most: int) -> int:
    """How many messages after the one at `start` repeat its size, prefix and sval length (so they are
    valid by the same checks); looked at in doubling chunks so a short run costs little."""
    row = _row_struct(key_end, size)
    expect = row.unpack_from(packet, start)
    view = memoryview(packet)
    rows, chunk = 0, 4
    while rows < most:
        n = min(chunk, most - rows)
        at = start + (rows + 1) * size
        got = list(row.iter_unpack(view[at:at + n * size]))
        if got.count(expect) == n:
            rows += n
            chunk *= 2
            continue
        for item in got:
            if item != expect:
                break
            rows += 1
        break
    return rows


class PacketScanner:
    """`scan_packet` for one client's stream.

    Apps send the same variables in the same order packet after packet. When a packet has the
    layout of the one before (same size, and in one struct pass: the same header, and per message
    the same length field, bytes from the type letters to the end of the key and sval length), its
    messages are valid by the same checks and the runs found before are the answer again. A layout
    is remembered once two packets in a row have had one size, so streams whose layout keeps
    changing pay nothing for it.
    """

    def __init__(self):
        self._last_size = -1
        self._shape: struct.Struct | None = None
        self._expect: tuple = ()
        self._runs: list[WireRun] = []

    def scan(self, packet: bytes) -> list[WireRun]:
        size = len(packet)
        if self._shape is not None and size == self._shape.size and self._shape.unpack_from(packet) == self._expect:
            return list(self._runs)
        runs = scan_packet(packet)
        if size == self._last_size:
            self._shape = _shape_struct("".join(_run_shape(run) for run in runs))
            self._expect, self._runs = self._shape.unpack_from(packet), runs
        self._last_size = size
        return list(runs)


def _run_shape(run: WireRun) -> str:
    """struct format of a run's messages picking out what fixes their layout (see PacketScanner)."""
    key_end, bounds = run.key_end, run.bounds
    if isinstance(bounds, range):
        return f"4s4x{key_end - 8}s24x4s{bounds.step - key_end - 28}x" * (len(bounds) - 1)
    return "".join(f"4s4x{key_end - 8}s24x4s{e - s - key_end - 28}x" for s, e in zip(bounds, bounds[1:]))


@functools.lru_cache(maxsize=64)
def _shape_struct(messages: str) -> struct.Struct:
    return struct.Struct("<4s5s" + messages)


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
        buf, pos = self._buf, self._pos
        if pos == len(buf) and type(data) is bytes:     # nothing pending: frame the chunk itself, no copy
            self._buf, self._pos = data, 0
            return
        if type(buf) is not bytearray:
            buf = bytearray(memoryview(buf)[pos:])
        elif pos:
            del buf[:pos]
        buf += data
        self._buf, self._pos = buf, 0

    def next_unit(self) -> bytes | None:
        buf, pos = self._buf, self._pos
        avail = len(buf) - pos
        if self._need_slot:
            if avail < PROTOCOL_SLOT_SIZE:
                return None
            self._need_slot = False
            self._pos = pos + PROTOCOL_SLOT_SIZE
            return bytes(memoryview(buf)[pos:self._pos])
        if avail < 4:
            return None
        (total,) = _INT.unpack_from(buf, pos)
        if total < PACKET_HEADER_SIZE or total > self.max_packet:
            raise FramingError(f"packet length {total} outside [{PACKET_HEADER_SIZE}, {self.max_packet}]")
        if avail < total:
            return None
        self._pos = end = pos + total
        return buf[pos:end] if type(buf) is bytes else bytes(memoryview(buf)[pos:end])

    def units(self, data: bytes) -> list[bytes]:
        """Feed `data` and return every unit it completes."""
        self.feed(data)
        out = []
        while (unit := self.next_unit()) is not None:
            out.append(unit)
        return out
