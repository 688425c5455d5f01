"""pymoos-style scripts, unchanged but for `from moosdb_py import pymoos`, against a real moosdb.

Each test reads like the pymoos scripts users write (comms with callbacks, wildcards, an active
queue, binary data); only the waits are poll loops with deadlines instead of `time.sleep`.
"""
from __future__ import annotations

import logging
import threading

import pytest

from helpers import wait_until
from moosdb_py import pymoos


@pytest.fixture(autouse=True)
def process_wide_time(monkeypatch):
    """Time warp and skew are process-wide in pymoos; every test starts from (and leaves) 1 and 0."""
    monkeypatch.setattr(pymoos, "_warp", 1.0)
    monkeypatch.setattr(pymoos, "_skew", 0.0)


def _collect(comms, into):
    """The usual on-mail callback: fetch, keep, return True."""
    def on_mail():
        into.extend(comms.fetch())
        return True
    return on_mail


def test_publish_subscribe_with_callbacks(moosdb_server, capsys):
    port = moosdb_server.port
    sub = pymoos.comms()
    pub = pymoos.comms()
    got = []
    sub.set_on_connect_callback(lambda: sub.register("DEPTH", 0) and sub.register("NOTE", interval=0))
    sub.set_on_mail_callback(_collect(sub, got))
    assert sub.run("localhost", port, "script_sub") and pub.run("localhost", port, "script_pub")
    assert sub.wait_until_connected(5000) and pub.wait_until_connected(5000)
    _settle(sub, got, "DEPTH", "NOTE")

    pub.notify("DEPTH", 12.5)
    pub.notify("NOTE", "héllo ✓")                       # UTF-8 on the wire, as pymoos sends it
    pub.notify("NOTE", "with aux", "aux_src")
    pub.notify("DEPTH", 7, 1234.5)                      # explicit time; ints post doubles
    pub.notify("DEPTH", 8.0, aux_src="kw", time=1500.0)
    wait_until(lambda: len(got) >= 5, timeout=5)

    depth, note, aux_note, stamped, keyword = got[:5]
    assert depth.name() == depth.key() == "DEPTH" and depth.is_name("DEPTH") and not depth.is_name("NOTE")
    assert depth.is_double() and not depth.is_string() and depth.double() == 12.5 and depth.double_aux() == -1
    assert abs(depth.time() - pymoos.time()) < 5 and depth.source() == "script_pub"
    assert depth.community() == "#1" and depth.source_aux() == ""
    assert note.is_string() and note.string() == "héllo ✓" and note.binary_data() == "héllo ✓".encode()
    assert aux_note.source_aux() == "aux_src"
    assert (stamped.double(), stamped.time()) == (7.0, 1234.5)
    assert (keyword.double(), keyword.source_aux(), keyword.time()) == (8.0, "kw", 1500.0)
    depth.trace()
    assert "DEPTH" in capsys.readouterr().out

    assert sub.get_moos_name() == "script_sub" and sub.get_community_name() == "#1"
    assert sub.get_description() == f"127.0.0.1:{port}"
    assert sub.get_registered() == ["DEPTH", "NOTE"] and sub.is_registered_for("NOTE")
    assert not sub.is_registered_for("DEPTH_X") and pub.get_published() == ["DEPTH", "NOTE"]
    assert sub.is_running() and sub.is_asynchronous() and sub.is_connected()
    assert pub.get_number_messages_sent() >= 5 and pub.get_number_bytes_sent() > 0
    assert sub.get_number_message_read() >= 5 and sub.get_number_bytes_read() > 0
    wait_until(lambda: pub.get_number_of_unsent_messages() == 0, timeout=5)
    assert sub.close(True) and pub.close(True)
    assert not sub.is_connected() and not sub.is_running()


def _settle(comms, got, *keys):
    """Wait until the DB holds `comms`'s on-connect registrations: a probe it posts after them
    comes back only once the DB has processed them (one client's messages stay in order)."""
    wait_until(lambda: all(comms.is_registered_for(k) for k in keys), timeout=5)
    probe = f"{comms.get_moos_name()}_SETTLED"
    comms.register(probe, 0)
    comms.notify(probe, 1.0)
    wait_until(lambda: any(m.name() == probe for m in got), timeout=5)
    comms.unregister(probe)
    got[:] = [m for m in got if m.name() != probe]


def test_wildcard_registration_and_unread_mail(moosdb_server):
    port = moosdb_server.port
    sub = pymoos.comms()
    sub.set_on_connect_callback(lambda: sub.register("NAV_*", "*", 0) and sub.register("?PEED", "uSim*", 0))
    sub.run("localhost", port, "wild_sub")
    sim = pymoos.comms()
    other = pymoos.comms()
    sim.run("localhost", port, "uSimMarine")
    other.run("localhost", port, "pOther")
    assert sim.wait_until_connected(5000) and other.wait_until_connected(5000) and sub.wait_until_connected(5000)
    got = []

    def nav_round():
        sim.notify("NAV_X", 1.0)
        sim.notify("SPEED", 2.0)
        other.notify("NAV_Y", 3.0)
        other.notify("XPEED", 4.0)          # matches ?PEED but not uSim*
        other.notify("DEPTH", 5.0)
        wait_until(lambda: sub.get_number_of_unread_messages() > 0, timeout=5)
        got.extend(sub.fetch())
        return {"NAV_X", "NAV_Y", "SPEED"} <= {m.name() for m in got}

    wait_until(nav_round, timeout=8, interval=0.05)
    assert {m.name() for m in got} == {"NAV_X", "NAV_Y", "SPEED"}
    assert sub.get_number_of_unread_messages() == 0 and sub.get_registered() == []
    for c in (sub, sim, other):
        c.close(True)


def test_active_queue_with_routes(moosdb_server, capsys, caplog):
    port = moosdb_server.port
    c = pymoos.comms()
    fetched, queued, threads = [], [], set()

    def on_queue(msg):
        threads.add(threading.current_thread().name)
        if msg.double() < 0:
            raise ValueError("negative depth")
        queued.append(msg.double())
        return True

    def on_connect():
        return c.register("DEPTH", 0) and c.register("SPEED", 0)

    c.set_on_connect_callback(on_connect)
    c.set_on_mail_callback(_collect(c, fetched))
    assert c.add_active_queue("depth_queue", on_queue) and not c.add_active_queue("depth_queue", on_queue)
    assert c.add_message_route_to_active_queue("depth_queue", "DEPTH")
    assert not c.add_message_route_to_active_queue("no_such_queue", "DEPTH")
    assert c.has_active_queue("depth_queue") and not c.has_active_queue("no_such_queue")
    c.print_message_to_active_queue_routing()
    assert "DEPTH -> depth_queue" in capsys.readouterr().out
    c.run("localhost", port, "queue_script")
    assert c.wait_until_connected(5000)
    _settle(c, fetched, "DEPTH", "SPEED")

    with caplog.at_level(logging.ERROR, logger="moosdb_py.comms"):
        for value in (1.0, -1.0, 2.0):      # the raising callback is reported; the queue carries on
            c.notify("DEPTH", value)
        c.notify("SPEED", 3.0)
        wait_until(lambda: queued == [1.0, 2.0] and fetched, timeout=5)
    assert "ActiveQueue depth_queue: caught an exception" in caplog.text and "negative depth" in caplog.text
    assert [m.name() for m in fetched] == ["SPEED"] and threads == {"ActiveQueue depth_queue"}

    assert c.remove_message_route_to_active_queue("depth_queue", "DEPTH")
    assert not c.remove_message_route_to_active_queue("depth_queue", "DEPTH")
    c.notify("DEPTH", 4.0)
    wait_until(lambda: any(m.name() == "DEPTH" for m in fetched), timeout=5)
    assert c.remove_active_queue("depth_queue") and not c.remove_active_queue("depth_queue")
    assert not c.has_active_queue("depth_queue") and queued == [1.0, 2.0]
    c.close(True)


def test_binary_data(moosdb_server):
    port = moosdb_server.port
    c = pymoos.comms()
    got = []
    c.set_on_connect_callback(lambda: c.register("IMAGE", 0) and c.register("RAW", 0))
    c.set_on_mail_callback(_collect(c, got))
    c.run("localhost", port, "binary_script")
    assert c.wait_until_connected(5000)
    _settle(c, got, "IMAGE", "RAW")
    payload = bytes(range(256)) * 4
    c.notify_binary("IMAGE", payload)
    c.notify("RAW", b"\xff\x00raw")                 # bytes through notify: a string, as in pymoos
    wait_until(lambda: len(got) >= 2, timeout=5)
    image, raw = got
    assert image.is_binary() and not image.is_string() and image.binary_data() == payload
    assert image.binary_data_size() == 1024
    assert raw.is_string() and raw.binary_data() == b"\xff\x00raw" and raw.binary_data_size() == 0
    raw.mark_as_binary()
    assert raw.is_binary() and raw.binary_data_size() == 5 and raw.binary_data() == b"\xff\x00raw"
    c.close(True)


def test_bad_input_and_callbacks_that_raise(moosdb_server, caplog):
    c = pymoos.comms()
    with pytest.raises(RuntimeError, match=r"call run\(\) before"):
        c.notify("X", 1.0)
    with pytest.raises(RuntimeError, match=r"call run\(\) before"):
        c.register("X", 0)
    with pytest.raises(ValueError, match="positive"):
        pymoos.set_moos_timewarp(0)
    calls = []

    def on_mail():
        calls.append(len(c.fetch()))
        raise KeyError("script bug")

    c.set_on_connect_callback(lambda: c.register("PING", 0))
    c.set_on_mail_callback(on_mail)
    c.run("localhost", moosdb_server.port, "raising_script")
    assert c.wait_until_connected(5000)
    with pytest.raises(TypeError, match="list"):
        c.notify("PING", [1, 2])
    with pytest.raises(TypeError, match="register"):
        c.register("A", "B")
    with caplog.at_level(logging.ERROR, logger="moosdb_py.comms"):
        wait_until(lambda: c.notify("PING", 1.0) and len(calls) >= 2, timeout=5, interval=0.1)
    assert "raising_script OnMail: caught an exception" in caplog.text and "script bug" in caplog.text
    assert c.is_connected()
    c.close(True)

    closer = pymoos.comms()
    closer.set_on_connect_callback(lambda: closer.close(True))    # closing from its own comms thread
    closer.run("localhost", moosdb_server.port, "closing_script")
    wait_until(lambda: not closer.is_running(), timeout=5)


def test_module_functions_tuning_and_comms_status(moosdb_server, capsys):
    assert pymoos.is_little_end_in() in (True, False) and pymoos.get_moos_timewarp() == 1.0
    assert abs(pymoos.time() - pymoos.local_time()) < 1e-3
    assert pymoos.set_moos_timewarp(10) and pymoos.get_moos_timewarp() == 10
    assert abs(pymoos.local_time() / pymoos.local_time(False) - 10) < 1e-6
    assert abs(pymoos.time(False) - pymoos.local_time(False)) < 1e-3
    pymoos.set_moos_timewarp(1)

    c = pymoos.comms()
    c.set_quiet(True)
    c.set_verbose_debug(True)
    c.set_verbose_debug(False)
    c.set_quiet(False)
    assert c.set_comms_tick(20)
    c.set_comms_control_timewarp_scale_factor(0.5)
    assert c.get_comms_control_timewarp_scale_factor() == 0.5
    c.do_local_time_correction(True)              # the DB is on this host: only asked for, it applies
    c.enable_comms_status_monitoring(True)
    c.run("localhost", moosdb_server.port, "status_script")
    assert c.wait_until_connected(5000)
    skew = c._client.db_skew
    assert abs(pymoos.time() - pymoos.local_time() - skew) < 1e-3 and abs(skew) < 1

    status = pymoos.moos_comms_status()
    wait_until(lambda: c.get_client_comms_status("status_script", status) and status.subscribes_, timeout=8)
    assert status.name_ == "status_script" and {"DB_QOS", "DB_RWSUMMARY"} <= set(status.subscribes_)
    assert status.recent_latency_ >= 0 and status.appraise() in (status.Excellent, status.Good, status.Fair)
    assert not c.get_client_comms_status("nobody", pymoos.moos_comms_status())
    statuses = pymoos.moos_comms_status_list()
    c.get_client_comms_statuses(statuses)
    assert "status_script" in [s.name_ for s in statuses]
    status.print()
    assert "status_script" in capsys.readouterr().out
    assert c.fetch() == []                         # DB_QOS and DB_RWSUMMARY went to their queue
    c.enable_comms_status_monitoring(False)
    assert not c.has_active_queue(pymoos.CLIENT_SUMMARIES)
    c.close(True)
