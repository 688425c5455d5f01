"""pCoordinates: tells the shoreside where this vehicle is when a planning cycle needs it.

pPathAssign plans from positions taken while the fleet holds station, so the
report goes out when station-keeping begins (STATION_KEEP turns true) and
whenever the shore asks again (REPORT_COORDINATES), never before the
navigation solution is known.
"""
from __future__ import annotations

from moosdb_py.app import MOOSApp
from moosdb_py.config import Param, Params
from moosdb_py.formats import FormatError, parse_bool
from oilspill_moos.messages import coordinates_report


class Coordinates(MOOSApp):
    """pCoordinates: posts VEHICLE_COORDINATES (from NAV_X/NAV_Y) when STATION_KEEP turns true
    and on every REPORT_COORDINATES request, for pPathAssign's planning cycle."""

    default_name = "pCoordinates"
    parameters = Params(Param("vname", str, "", "name put in the report; default: the mission's Community"))
    example_config = """\
ProcessConfig = pCoordinates
{
  AppTick   = 4
  CommsTick = 4

  // Name put in the report; default: the mission's Community
  vname = abe
}
"""
    interface = """\
SUBSCRIPTIONS:
  NAV_X, NAV_Y          position of this vehicle (local metres)
  STATION_KEEP          a change to "true" triggers a report
  REPORT_COORDINATES    any post triggers a report (the shore asking again)

PUBLICATIONS:
  VEHICLE_COORDINATES   "vname=abe,x=12.30,y=-40.00,utc=1712345678.90"
"""

    def on_startup(self) -> None:
        community = self.mission.community if self.mission is not None else ""
        self.vname = (self.read_settings()["vname"] or community or self.name).lower()
        self.nav_x: float | None = None
        self.nav_y: float | None = None
        self.station_keeping = False
        self.pending = False
        self.reports = 0

    def on_connect(self) -> None:
        for key in ("NAV_X", "NAV_Y", "STATION_KEEP", "REPORT_COORDINATES"):
            self.register(key)

    def on_new_mail(self, mail) -> None:
        for msg in mail:
            if msg.key == "NAV_X" and msg.is_double():
                self.nav_x = msg.double
            elif msg.key == "NAV_Y" and msg.is_double():
                self.nav_y = msg.double
            elif msg.key == "STATION_KEEP":
                try:
                    keeping = parse_bool(str(msg.value))
                except FormatError:
                    keeping = False
                self.pending |= keeping and not self.station_keeping
                self.station_keeping = keeping
            elif msg.key == "REPORT_COORDINATES":
                self.pending = True
        self._report()

    def iterate(self) -> None:
        self._report()

    def _report(self) -> None:
        if self.pending and self.nav_x is not None and self.nav_y is not None:
            self.notify("VEHICLE_COORDINATES", coordinates_report(self.vname, self.nav_x, self.nav_y,
                                                                  self.moos_time()))
            self.pending = False
            self.reports += 1

    def status_fields(self) -> dict:
        return {"vname": self.vname, "reports": self.reports}


main = Coordinates.main
