"""The MOOSApp shell of an app whose logic is a pure state machine.

The machine takes mail as `on_mail(key, value, now, sender)`, answers `iterate(now)` with the
(key, value) postings, and leaves what it could not use in its `warnings` list; the shell only
registers, moves mail in, logs the warnings and posts. uFldNodeComms, uFldCollisionDetect and
pContactMgrV20 share it.
"""
from __future__ import annotations

import logging

from moosdb_py.app import MOOSApp

log = logging.getLogger(__name__)


class MachineApp(MOOSApp):
    """Subclasses set `machine` in on_startup and list the variables they read in `inputs`."""

    inputs: tuple[str, ...] = ()
    machine = None

    def registrations(self) -> list[str]:
        """Everything to register for; a subclass adds what its configuration names."""
        return list(self.inputs)

    def on_connect(self) -> None:
        for key in self.registrations():
            self.register(key)

    def on_new_mail(self, mail) -> None:
        now = self.moos_time()
        for msg in mail:
            self.machine.on_mail(msg.key, msg.value, now, msg.sender)
        while self.machine.warnings:
            log.warning("%s: %s", self.name, self.machine.warnings.pop(0))

    def iterate(self) -> None:
        for key, value in self.machine.iterate(self.moos_time()):
            self.notify(key, value)
