"""CMOOSMsg in Python: one MOOS message, with the field names and defaults the C++ code uses."""
from __future__ import annotations

import time as _time
from dataclasses import dataclass

# Message-type letters (MOOSMsg.h); the DB and client dispatch on these.
NOTIFY = "N"
REGISTER = "R"
UNREGISTER = "U"
WILDCARD_REGISTER = "*"
WILDCARD_UNREGISTER = "/"
COMMAND = "C"
SERVER_REQUEST = "Q"
TIMING = "T"
WELCOME = "W"
POISON = "K"
DATA = "i"
NULL_MSG = "."
NOT_SET = "~"
ANONYMOUS = "A"
TERMINATE = "^"
MSG_TYPES = frozenset("NRU*/CQTWKi.~A^")

DOUBLE = "D"
STRING = "S"
BINARY = "B"
DATA_TYPES = frozenset("DSB")
WIRE_DATA_TYPES = DATA_TYPES | {NOT_SET}   # a C++ DB answers ALL with '~' for never-written variables

SERVER_REQUEST_ID = -2
ASYNC_TIMING_KEY = "_async_timing"


_new = object.__new__


def moos_time(time_warp: float = 1.0) -> float:
    """MOOS time: the wall clock scaled by the time warp, as every MOOS process stamps its mail."""
    return _time.time() * time_warp


@dataclass(slots=True)
class MOOSMsg:
    """A MOOS message. Unused doubles are -1 and unset strings empty, as on the wire.

    `string` holds the sval field as latin-1 text (lossless for any bytes); for binary ('B')
    messages the payload is in `binary` instead.
    """

    msg_type: str = NULL_MSG
    data_type: str = DOUBLE
    key: str = ""
    double: float = -1.0
    string: str = ""
    binary: bytes = b""
    source: str = ""
    source_aux: str = ""
    community: str = ""
    time: float = -1.0
    id: int = -1
    double_aux: float = -1.0

    @classmethod
    def notification(cls, key: str, value: float | str | bytes, *, time: float, source: str = "",
                     source_aux: str = "", msg_id: int = -1) -> "MOOSMsg":
        """A notify carrying a double, string or binary value, typed as the C++ client types it."""
        kind = type(value)
        if kind is float or kind is str:     # the usual cases first, fields set directly (as `copy`)
            out = _new(MOOSMsg)
            out.msg_type, out.key, out.binary, out.community, out.double_aux = NOTIFY, key, b"", "", -1.0
            out.source, out.source_aux, out.time, out.id = source, source_aux, time, msg_id
            if kind is float:
                out.data_type, out.double, out.string = DOUBLE, value, ""
            else:
                out.data_type, out.double, out.string = STRING, -1.0, value
            return out
        if isinstance(value, (bytes, bytearray, memoryview)):
            return cls(NOTIFY, BINARY, key, binary=bytes(value), source=source, source_aux=source_aux,
                       time=time, id=msg_id)
        if isinstance(value, str):
            return cls(NOTIFY, STRING, key, string=value, source=source, source_aux=source_aux,
                       time=time, id=msg_id)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError(f"MOOS values are float, str or bytes, not {type(value).__name__} ({key})")
        return cls(NOTIFY, DOUBLE, key, double=float(value), source=source, source_aux=source_aux,
                   time=time, id=msg_id)

    def copy(self) -> "MOOSMsg":
        """An independent copy (the DB hands each in-process subscriber its own), its fields set directly:
        half the cost of calling the dataclass's __init__."""
        out = _new(MOOSMsg)
        out.msg_type, out.data_type, out.key, out.double = self.msg_type, self.data_type, self.key, self.double
        out.string, out.binary, out.source, out.source_aux = self.string, self.binary, self.source, self.source_aux
        out.community, out.time, out.id, out.double_aux = self.community, self.time, self.id, self.double_aux
        return out

    @property
    def value(self) -> float | str | bytes:
        if self.data_type == DOUBLE:
            return self.double
        if self.data_type == BINARY:
            return self.binary
        return self.string

    @property
    def sender(self) -> str:
        """`source@community` ('?' for an unknown part): whom an error about this mail names."""
        return f"{self.source or '?'}@{self.community or '?'}"

    @property
    def sval_bytes(self) -> bytes:
        """The raw sval field."""
        return self.binary if self.data_type == BINARY else self.string.encode("latin-1")

    def is_double(self) -> bool:
        return self.data_type == DOUBLE

    def is_string(self) -> bool:
        return self.data_type == STRING

    def is_binary(self) -> bool:
        return self.data_type == BINARY

    def __str__(self) -> str:
        value = f"<{len(self.binary)} bytes>" if self.is_binary() else self.value
        return f"{self.msg_type} {self.key}={value!r} from {self.source or '?'} at {self.time:.3f}"
