"""The demo's shoreside Observer gets back what it missed when the DB dropped it (its client time-out):
on reconnecting its subscriptions come back, and with them the values in force (the loop, each
vehicle's arc, the phase), with no phase counted twice."""
import asyncio

from helpers import async_wait_until
from moosdb_py.client import MOOSClient
from moosdb_py.moosdb import MOOSDB
from oilspill_moos.messages import points_update, polygon_string
from oilspill_moos.oilspill_mission import Observer

LOOP_1 = [(0.0, 0.0), (100.0, 0.0), (100.0, 100.0)]
LOOP_2 = [(0.0, 0.0), (300.0, 0.0), (300.0, 300.0), (0.0, 300.0)]


def test_the_observer_recovers_the_loop_arcs_and_phase_it_missed_while_dropped():
    async def scenario():
        db = MOOSDB(port=0, community="shoreside", time_warp=5.0)
        await db.start()
        observer = Observer("127.0.0.1", db.port, 5.0)
        observer.client.reconnect_interval = 0.3
        planner = MOOSClient("pPathAssign", port=db.port, time_warp=5.0)
        tasks = [asyncio.create_task(c.run()) for c in (observer.client, planner)]
        try:
            assert await observer.client.wait_connected(5) and await planner.wait_connected(5)
            await async_wait_until(lambda: "OILSPILL_REGION" in db.core.clients["uDemoObserver"].subscribed)
            planner.notify("OILSPILL_PHASE", "STARTING-POSITION")
            planner.notify("OILSPILL_REGION", polygon_string(LOOP_1, "standoff"))
            planner.notify("VIEW_POLYGON", polygon_string(LOOP_1, "standoff"))
            planner.notify("OIL_PATH_UPDATES_ABE", points_update(LOOP_1[:2], repeat="forever"))
            await async_wait_until(lambda: observer.regions and "abe" in observer.loops)
            assert observer.phase == "STARTING-POSITION" and observer.regions == [LOOP_1]

            db.transmit(db.core.drop(db.core.clients["uDemoObserver"], "silent (test)", db.now()))
            await async_wait_until(lambda: not observer.client.connected)
            # what the observer misses: the next cycle's loop, arcs and phase, and a later VIEW_POLYGON
            planner.notify("OILSPILL_REGION", polygon_string(LOOP_2, "standoff"))
            planner.notify("OIL_PATH_UPDATES_ABE", points_update(LOOP_2[1:3], repeat="forever"))
            planner.notify("OIL_PATH_UPDATES_BEN", points_update(LOOP_2[2:], repeat="forever"))
            planner.notify("OILSPILL_PHASE", "OIL-PATH")
            planner.notify("VIEW_POLYGON", polygon_string(LOOP_2, "oil_truth"))

            await async_wait_until(lambda: observer.client.connected and observer.phase == "OIL-PATH", timeout=10)
            await async_wait_until(lambda: len(observer.regions) == 2 and "ben" in observer.loops)
            assert observer.regions == [LOOP_1, LOOP_2]                # the truth's VIEW_POLYGON is no loop
            assert observer.loops == {"abe": LOOP_2[1:3], "ben": LOOP_2[2:]}
            assert observer.phase_count == {"STARTING-POSITION": 1, "OIL-PATH": 1}
            # and again: a reconnection with nothing new adds nothing
            db.transmit(db.core.drop(db.core.clients["uDemoObserver"], "silent (test)", db.now()))
            await async_wait_until(lambda: not observer.client.connected)
            await async_wait_until(lambda: "uDemoObserver" in db.core.clients, timeout=10)
            await asyncio.sleep(0.3)
            assert observer.regions == [LOOP_1, LOOP_2] and observer.phase_count == {"STARTING-POSITION": 1,
                                                                                       "OIL-PATH": 1}
        finally:
            for client in (observer.client, planner):
                client.close()
            await asyncio.wait_for(asyncio.gather(*tasks), 5)
            db.close()
    asyncio.run(asyncio.wait_for(scenario(), 40))
