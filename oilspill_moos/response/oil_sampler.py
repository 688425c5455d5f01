"""pOilSampler: the vehicle's side of the oil sensor.

Every `sample_interval` (warped) seconds, while the vehicle is in one of `sample_phases`, it asks
the sensor (`OIL_SENSOR_REQUEST`, bridged to the shoreside's uFldOilSensor) what lies at its
position; each answer (`OIL_SENSOR_REPORT`, qbridged back) becomes an `OIL_OBSERVATION`, which the
node broker bridges to the shoreside for fusion. A sensor that stays silent never holds the
vehicle up: unanswered requests are only counted.
"""
from __future__ import annotations

import math

from moosdb_py.app import MOOSApp
from moosdb_py.config import Param, Params
from oilspill_moos.messages import ObservationRejected, format_observation, format_request, parse_observation

SUBSCRIPTIONS = ("NAV_X", "NAV_Y", "OILSPILL_PHASE", "OIL_SENSOR_REPORT")


SAMPLER_PARAMS = Params(
    Param("vname", str, "", "the vehicle's name in requests (default: the mission's Community)"),
    Param("sample_interval", float, 5.0, "s (mission time) between sensor requests", lo=0.01),
    Param("sample_phases", str, "STARTING-POSITION, OIL-PATH", "OILSPILL_PHASE values to sample in; any: always"),
)


class OilSampler(MOOSApp):
    """pOilSampler: samples the oil sensor at a fixed rate on the containment loop and in transit,
    and reports detections and non-detections as OIL_OBSERVATION (position, time, oil flag)."""

    default_name = "pOilSampler"
    parameters = SAMPLER_PARAMS
    example_config = """\
ProcessConfig = pOilSampler
{
  AppTick   = 4
  CommsTick = 4

  vname           = abe          // default: the mission's Community
  sample_interval = 5            // s (mission time) between sensor requests
  sample_phases   = STARTING-POSITION, OIL-PATH   // OILSPILL_PHASE values to sample in; any: always
}
"""
    interface = """\
SUBSCRIPTIONS:
  NAV_X, NAV_Y          this vehicle's position (local metres)
  OILSPILL_PHASE        the phase pPathAssign has put the vehicle in (qbridged)
  OIL_SENSOR_REPORT     the sensor's answer (uFldOilSensor, qbridged)

PUBLICATIONS:
  OIL_SENSOR_REQUEST    "vname=abe,id=17,x=..,y=.." (bridged to the shoreside)
  OIL_OBSERVATION       "vname=abe,id=17,utc=..,x=..,y=..,oil=1,range=15[,thickness=..]"
                        (bridged to the shoreside; see docs/feedback.md)
"""

    def on_startup(self) -> None:
        community = self.mission.community if self.mission is not None else ""
        v = self.read_settings()
        self.vname = (v["vname"] or community or self.name).lower()
        self.sample_interval = v["sample_interval"]
        phases = v["sample_phases"]
        self.phases = None if phases.lower() == "any" else {p.strip().upper() for p in phases.split(",") if p.strip()}
        self.nav_x = self.nav_y = None
        self.phase = ""
        self.next_id = 1
        self.last_request = -math.inf
        self.pending: set[int] = set()
        self.reported = self.refused = 0

    def on_connect(self) -> None:
        for key in SUBSCRIPTIONS:
            self.register(key)

    def on_new_mail(self, mail) -> None:
        for msg in mail:
            if msg.key in ("NAV_X", "NAV_Y"):
                if msg.is_double():
                    setattr(self, msg.key.lower(), msg.double)
            elif msg.key == "OILSPILL_PHASE":
                self.phase = str(msg.value).strip().upper()
            elif msg.key == "OIL_SENSOR_REPORT":
                self._report(msg)

    def _report(self, msg) -> None:
        text = str(msg.value)
        try:
            obs = parse_observation(text)
            if obs.vname != self.vname or obs.id not in self.pending:
                raise ObservationRejected(f"answer to a request this vehicle did not make: {text!r}")
        except ObservationRejected as exc:
            self.refused += 1
            self.notify("OIL_SAMPLER_WARNING", f"{msg.sender}: {exc}")
            return
        self.pending.discard(obs.id)
        self.notify("OIL_OBSERVATION", format_observation(obs))
        self.reported += 1

    def sampling(self) -> bool:
        return self.nav_x is not None and self.nav_y is not None and (self.phases is None or self.phase in self.phases)

    def iterate(self) -> None:
        now = self.moos_time()
        if not self.sampling() or now - self.last_request < self.sample_interval:
            return
        self.last_request = now
        ident, self.next_id = self.next_id, self.next_id + 1
        self.pending = {i for i in self.pending if i > ident - 100} | {ident}   # forget long-lost requests
        self.notify("OIL_SENSOR_REQUEST", format_request(self.vname, ident, self.nav_x, self.nav_y))

    def status_fields(self) -> dict:
        return {"requested": self.next_id - 1, "reported": self.reported, "unanswered": len(self.pending),
                "refused": self.refused, "phase": self.phase or "-"}


main = OilSampler.main
