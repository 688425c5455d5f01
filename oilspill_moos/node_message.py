"""NODE_MESSAGE as the field apps read it: `src_node=..,dest_node=..|dest_group=..,var_name=..,
string_val=..|double_val=..`, a quoted string_val keeping its commas (MOOS's parseStringQ).

uFldNodeComms relays it and uFldMessageHandler posts what it carries; node reports are read with
`behaviors.contacts.NodeRecord`, which the helm's contact behaviours share.
"""
from __future__ import annotations

from dataclasses import dataclass

from behaviors.contacts import NodeRecordError
from moosdb_py.formats import FormatError, parse_number, parse_pairs


@dataclass(frozen=True)
class NodeMessage:
    """A NODE_MESSAGE: a variable and value one vehicle sends to another (or to a group)."""

    src_node: str
    dest_node: str
    dest_group: str
    var_name: str
    string_val: str | None
    double_val: float | None
    text: str

    @classmethod
    def parse(cls, text: str) -> "NodeMessage":
        """Read and check a message: a source, a destination (node or group), a variable, one value."""
        try:
            fields = parse_pairs(text, unquoted=True)
        except FormatError as exc:
            raise NodeRecordError(f"NODE_MESSAGE {text!r}: {exc}") from None
        double_text = fields.get("double_val")
        double_val = None
        if double_text is not None:
            try:
                double_val = parse_number(double_text)
            except FormatError:
                raise NodeRecordError(f"double_val={double_text!r} is not a number in {text!r}") from None
        message = cls(src_node=fields.get("src_node", ""), dest_node=fields.get("dest_node", ""),
                      dest_group=fields.get("dest_group", ""), var_name=fields.get("var_name", ""),
                      string_val=fields.get("string_val"), double_val=double_val, text=text)
        missing = [what for what, ok in (("src_node", message.src_node),
                                         ("dest_node or dest_group", message.dest_node or message.dest_group),
                                         ("var_name", message.var_name)) if not ok]
        if missing:
            raise NodeRecordError(f"NODE_MESSAGE without {', '.join(missing)}: {text!r}")
        if message.string_val and double_val is not None:
            raise NodeRecordError(f"NODE_MESSAGE with both string_val and double_val: {text!r}")
        return message

    @property
    def value(self) -> str | float:
        """What the receiver posts: the string value, else the number (0 when neither is given)."""
        if self.string_val:
            return self.string_val
        return self.double_val if self.double_val is not None else 0.0

    def length(self) -> int:
        """The size uFldNodeComms' max_msg_length limits: the string's characters, at least 2 (a number)."""
        return max(2, len(self.string_val or ""))
