"""uFldMessageHandler: a vehicle posts the variable a NODE_MESSAGE carries.

`MessageInbox` is pure: each NODE_MESSAGE is counted, checked and, when addressed to this vehicle
(its name, `all`, or only a group), turned into one posting of `var_name` with the string or
double value, the source node as the posting's source aux. UMH_SUMMARY_MSGS totals what arrived.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

from moosdb_py.app import MOOSApp
from moosdb_py.config import Param, Params
from behaviors.contacts import NodeRecordError
from oilspill_moos.node_message import NodeMessage

log = logging.getLogger(__name__)

SUMMARY_EVERY = 100   # iterations between summaries when no mail arrives


@dataclass(frozen=True)
class Delivery:
    """One posting a message asks for."""

    var: str
    value: str | float
    source_aux: str


@dataclass
class MessageInbox:
    """The message checks of uFldMessageHandler, free of I/O."""

    community: str
    strict_addressing: bool = False
    total: int = 0
    valid: int = 0
    rejected: int = 0
    problem: str = ""   # why the last message was invalid ("" if it was not)

    def receive(self, text: str) -> Delivery | None:
        """The posting for a NODE_MESSAGE, or None if it is invalid or addressed elsewhere."""
        self.total += 1
        try:
            message = NodeMessage.parse(text)
        except NodeRecordError as exc:
            self.problem = str(exc)
            return None
        self.problem = ""
        self.valid += 1
        dest = message.dest_node
        if (dest and dest != "all" and dest != self.community) or (self.strict_addressing and dest in ("", "all")):
            self.rejected += 1
            return None
        return Delivery(message.var_name, message.value, message.src_node)

    def summary(self) -> str:
        return f"total={self.total},valid={self.valid},rejected={self.rejected}"


class MessageHandler(MOOSApp):
    """uFldMessageHandler: posts the variable and value of each NODE_MESSAGE addressed to this vehicle.

    A message `src_node=alpha,dest_node=bravo,var_name=FOO,string_val=bar` arriving at bravo posts
    FOO = "bar" (double_val posts a number), with the source node as source aux. Messages for
    another vehicle are rejected; with strict_addressing, so are those to all or to a group only.
    UMH_SUMMARY_MSGS = total=14,valid=12,rejected=2 after new mail (and every 100 iterations).
    """

    default_name = "uFldMessageHandler"
    parameters = Params(Param("strict_addressing", bool, False,
                              "true: reject messages not addressed to this vehicle by name"))
    example_config = """\
ProcessConfig = uFldMessageHandler
{
  AppTick   = 4
  CommsTick = 4

  strict_addressing = false   // true: reject messages not addressed to this vehicle by name
}
"""
    interface = """\
SUBSCRIPTIONS:
  NODE_MESSAGE = src_node=alpha,dest_node=bravo,var_name=FOO,string_val=BAR
PUBLICATIONS:
  <var_name> = <string_val or double_val>   (source aux: the src_node)
  UMH_SUMMARY_MSGS = total=14,valid=12,rejected=2
"""

    def on_startup(self) -> None:
        strict = self.read_settings()["strict_addressing"]
        community = (self.mission.community if self.mission is not None else "") or "unknown"
        self.inbox = MessageInbox(community, strict)
        self.new_mail = False

    def on_connect(self) -> None:
        self.register("NODE_MESSAGE")

    def on_new_mail(self, mail) -> None:
        for msg in mail:
            if msg.key != "NODE_MESSAGE":
                continue
            self.new_mail = True
            delivery = self.inbox.receive(msg.string)
            if delivery is not None:
                self.notify(delivery.var, delivery.value, source_aux=delivery.source_aux)
            elif self.inbox.problem:
                log.warning("%s: NODE_MESSAGE from %s: %s", self.name, msg.sender, self.inbox.problem)

    def iterate(self) -> None:
        if self.new_mail or self.iterations % SUMMARY_EVERY == 1:
            self.notify("UMH_SUMMARY_MSGS", self.inbox.summary())
        self.new_mail = False

    def status_fields(self) -> dict:
        return {"total": self.inbox.total, "valid": self.inbox.valid, "rejected": self.inbox.rejected}


main = MessageHandler.main
