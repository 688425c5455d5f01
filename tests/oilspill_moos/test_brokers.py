"""The broker handshake as pure state machines: host records, pings, acks, bridge requests."""
from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from oilspill_moos.field.node_broker import (
    HostRecord,
    NodeBrokerState,
    node_bridges,
    parse_bridge,
    parse_shore_route,
)
from oilspill_moos.field.bridges import parse_output_summary
from oilspill_moos.field.shore_broker import (
    ShoreBrokerState,
    expand_source,
    parse_vnode_route,
    shore_bridges,
)

SHORE_INFO = "community=shoreside,hostip=localhost,port_db=9000,pshare_iroutes=localhost:9200,timewarp=10"
ABE_INFO = "community=abe,hostip=localhost,port_db=9001,pshare_iroutes=localhost:9201,timewarp=10"

value_text = st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789.:&_", min_size=1, max_size=12)


@settings(max_examples=60)
@given(st.fixed_dictionaries({"community": value_text}, optional={
    "hostip": value_text, "port_db": value_text, "pshare_iroutes": value_text, "timewarp": value_text,
    "time": value_text, "key": value_text, "keyword": value_text}))
def test_host_record_round_trip(values):
    record = HostRecord(**values)
    assert HostRecord.parse(record.spec()) == record


def test_host_record_wire_order_any_order_and_vname_alias():
    record = HostRecord.parse("timewarp=10,key=0,vname=abe,hostip=1.2.3.4,port_db=9001,time=5.00")
    assert record.spec() == "community=abe,hostip=1.2.3.4,port_db=9001,timewarp=10,time=5.00,key=0"
    assert HostRecord.parse("community=a,status=ok,status=10").status == "10"  # the last one wins
    with pytest.raises(ValueError, match="without community"):
        HostRecord.parse("hostip=1.2.3.4,port_db=9001")
    with pytest.raises(ValueError, match="key=value"):
        HostRecord.parse("community=abe,garbage")


def test_config_lines():
    assert parse_bridge("src = NODE_REPORT_LOCAL , alias = NODE_REPORT", "b") == ("NODE_REPORT_LOCAL", "NODE_REPORT")
    assert parse_bridge("src=VIEW_POINT", "b") == ("VIEW_POINT", "VIEW_POINT")
    with pytest.raises(ValueError, match="no src"):
        parse_bridge("alias=X", "bridge #1")
    assert parse_shore_route("pshare_route = localhost:9200", "t") == "localhost:9200"
    with pytest.raises(ValueError, match="pshare_route"):
        parse_shore_route("pshare_route=localhost", "try_shore_host #1")
    assert parse_vnode_route("route=10.0.0.5", "t") == "10.0.0.5:9200"
    assert parse_vnode_route("route=10.0.0.5:9305", "t") == "10.0.0.5:9305"
    with pytest.raises(ValueError, match="NODE_MESSAGE_LOCAL"):
        node_bridges(["src=NODE_MESSAGE_LOCAL,alias=NODE_MESSAGE", "src=MEDIATED_MESSAGE_LOCAL"], {})
    bridges = node_bridges(["src=NODE_REPORT_LOCAL,alias=NODE_REPORT", "src=APPCAST"], {"auto_bridge_realmcast": False})
    assert bridges == [("NODE_REPORT_LOCAL", "NODE_REPORT"), ("APPCAST", "APPCAST"), ("NODE_PSHARE_VARS", "NODE_PSHARE_VARS")]


def test_qbridge_expansion():
    bridges, qvars = shore_bridges(["src=RETURN_$V,alias=RETURN", "src=UP_$N"], ["DEPLOY, STATION_KEEP"],
                                   {"auto_bridge_appcast": False})
    assert qvars == ["DEPLOY", "STATION_KEEP", "REALMCAST_REQ"]
    assert bridges[:2] == [("DEPLOY_ALL", "DEPLOY"), ("DEPLOY_$V", "DEPLOY")]
    assert ("RETURN_$V", "RETURN") in bridges and ("UP_$N", "UP_$N") in bridges
    assert bridges[-1] == ("MISSION_HASH", "MISSION_HASH")
    assert expand_source("X_$V_$v_$N", "ben", 2) == "X_BEN_ben_2"
    with pytest.raises(ValueError, match="must not contain"):
        shore_bridges([], ["DEPLOY=true"], {})


def test_output_summary_parse():
    summary = "NODE_BROKER_ACK_ABE->NODE_BROKER_ACK:localhost:9201, X->Y:10.0.0.1:9000 & Z:224.1.1.11:24468:multicast_8"
    assert parse_output_summary(summary) == {
        ("NODE_BROKER_ACK_ABE", "NODE_BROKER_ACK", "localhost:9201"),
        ("X", "Y", "10.0.0.1:9000"),
        ("X", "Z", "224.1.1.11:24468:multicast_8"),
    }


def make_node() -> NodeBrokerState:
    node = NodeBrokerState("abe", bridges=[("NODE_REPORT_LOCAL", "NODE_REPORT")])
    node.add_shore("localhost:9200")
    return node


def test_node_pings_until_acked_then_bridges_once():
    node = make_node()
    posts = node.iterate(100.0)
    assert posts == [("PSHARE_CMD", "cmd=output,src_name=NODE_BROKER_PING_0,dest_name=NODE_BROKER_PING,route=localhost:9200")]
    node.on_host_info(ABE_INFO, "abe")
    posts = dict(node.iterate(100.5))
    assert posts["NODE_BROKER_PING_0"] == ABE_INFO + ",time=100.50,key=0"
    assert "NODE_BROKER_PING_0" not in dict(node.iterate(101.0))  # 5 s between unanswered pings
    assert "NODE_BROKER_PING_0" in dict(node.iterate(105.5))
    assert node.on_ack(SHORE_INFO + ",status=ok,key=0,id=1", "abe", 106.0) == []  # our own community: not an ack
    posts = node.on_ack(SHORE_INFO + ",status=ok,key=0,id=1", "shoreside", 106.0)
    assert posts == [("NODE_PSHARE_VARS", "NODE_REPORT"),
                     ("PSHARE_CMD", "cmd=output,src_name=NODE_REPORT_LOCAL,dest_name=NODE_REPORT,route=localhost:9200")]
    assert node.shores[0].community == "shoreside" and node.shores[0].timewarp == "10"
    assert node.on_ack(SHORE_INFO + ",status=ok,key=0,id=2", "shoreside", 107.0) == [("NODE_PSHARE_VARS", "NODE_REPORT")]
    assert dict(node.iterate(108.0)) == {}  # answered: no PSHARE_CMD, next ping 20 s after the last
    assert "NODE_BROKER_PING_0" in dict(node.iterate(125.6))


def test_node_input_summary_stands_in_for_phi_host_info():
    node = make_node()
    node.on_input_summary("localhost:9201", "localhost", 9001, 10.0)
    assert dict(node.iterate(1.0))["NODE_BROKER_PING_0"] == ABE_INFO + ",time=1.00,key=0"
    node.on_host_info("community=abe,hostip=10.1.1.1,pshare_iroutes=10.1.1.1:9201,timewarp=10", "abe")
    node.on_input_summary("localhost:9999", "localhost", 9001, 10.0)  # pHostInfo's record wins
    assert node.host_record.hostip == "10.1.1.1"
    node.on_host_info("community=ben,hostip=9.9.9.9", "ben")  # not our community
    assert node.host_record.hostip == "10.1.1.1"


def test_node_ack_with_bad_key_warns_and_uses_the_only_shore():
    node = make_node()
    posts = node.on_ack(SHORE_INFO + ",status=ok,id=3", "shoreside", 5.0)
    assert node.warnings and "bad key" in node.warnings[0]
    assert ("PSHARE_CMD", "cmd=output,src_name=NODE_REPORT_LOCAL,dest_name=NODE_REPORT,route=localhost:9200") in posts


def test_node_try_shore_host_added_at_run_time():
    node = make_node()
    assert node.add_shore("10.0.0.9:9200")
    assert not node.add_shore("10.0.0.9:9200") and "twice" in node.warnings[-1]
    posts = node.iterate(0.0)
    assert [v for k, v in posts if k == "PSHARE_CMD"][1].endswith("src_name=NODE_BROKER_PING_1,dest_name=NODE_BROKER_PING,route=10.0.0.9:9200")


def make_shore(**kwargs) -> ShoreBrokerState:
    bridges, qvars = shore_bridges(["src=RETURN_$V,alias=RETURN"], ["DEPLOY"], {"auto_bridge_appcast": False,
                                                                               "auto_bridge_realmcast": False,
                                                                               "auto_bridge_mhash": False})
    shore = ShoreBrokerState("shoreside", bridges=bridges, qbridge_vars=qvars, **kwargs)
    shore.on_host_info(SHORE_INFO, "shoreside")
    return shore


def test_shore_acks_and_bridges_a_new_node():
    shore = make_shore()
    assert shore.on_ping(ABE_INFO + ",time=1.00,key=0", "shoreside", 1.0) == []  # local: ignored
    posts = shore.on_ping(ABE_INFO + ",time=1.00,key=0", "abe", 1.0)
    assert [v for _, v in posts] == [
        "cmd=output,src_name=NODE_BROKER_ACK_ABE,dest_name=NODE_BROKER_ACK,route=localhost:9201",
        "cmd=output,src_name=DEPLOY_ALL,dest_name=DEPLOY,route=localhost:9201",
        "cmd=output,src_name=DEPLOY_ABE,dest_name=DEPLOY,route=localhost:9201",
        "cmd=output,src_name=RETURN_ABE,dest_name=RETURN,route=localhost:9201",
    ]
    posts = shore.iterate(1.5)
    assert ("NODE_BROKER_ACK_ABE", SHORE_INFO + ",status=ok,key=0,id=1") in posts
    assert ("NODE_BROKER_VACK", "abe") in posts and ("UFSB_NODE_COUNT", 1.0) in posts
    assert ("UFSB_QBRIDGE_VARS", "DEPLOY") in posts
    assert ("NODE_BROKER_ACK_ABE", SHORE_INFO + ",status=ok,key=0,id=2") in shore.iterate(2.0)
    assert not any(k.startswith("NODE_BROKER_ACK") for k, _ in shore.iterate(11.5))  # no ping for 10 s
    assert shore.on_ping(ABE_INFO + ",time=12.00,key=0", "abe", 12.0) == []  # known node, same routes


def test_shore_bridge_rounds_skip_what_pshare_already_shares():
    shore = make_shore()
    shore.on_ping(ABE_INFO + ",key=0", "abe", 0.0)
    shore.on_output_summary("DEPLOY_ALL->DEPLOY:localhost:9201, NODE_BROKER_ACK_ABE->NODE_BROKER_ACK:localhost:9201")
    cmds = [v for k, v in shore.iterate(5.0) if k == "PSHARE_CMD"]
    assert cmds == ["cmd=output,src_name=DEPLOY_ABE,dest_name=DEPLOY,route=localhost:9201",
                    "cmd=output,src_name=RETURN_ABE,dest_name=RETURN,route=localhost:9201"]
    assert not [k for k, _ in shore.iterate(7.0) if k == "PSHARE_CMD"]  # next round waits 5 + 3 s
    assert [k for k, _ in shore.iterate(13.0) if k == "PSHARE_CMD"]


def test_shore_status_mismatches_and_remote_hosts():
    shore = make_shore(keyword="lake")
    shore.on_ping(ABE_INFO + ",keyword=lake,key=0", "abe", 0.0)
    shore.on_ping("community=ben,hostip=10.0.0.2,pshare_iroutes=localhost:9202,timewarp=5,keyword=lake,key=0", "ben", 0.0)
    shore.on_ping("community=cal,pshare_iroutes=localhost:9203,timewarp=10,key=0", "cal", 0.0)
    assert shore.nodes["abe"].status == "ok"
    assert shore.nodes["ben"].status == "timewarp (10!=5)"
    assert shore.nodes["ben"].routes == "10.0.0.2:9202"  # localhost means the vehicle's own host
    assert shore.nodes["cal"].status == "keyword_mismatch"
    assert [src for src, _ in shore.node_bridges(shore.nodes["cal"])] == ["NODE_BROKER_ACK_CAL"]
    assert any("keyword_mismatch" in w for w in shore.warnings)


def test_shore_node_moved_to_new_port_is_bridged_again():
    shore = make_shore()
    shore.on_ping(ABE_INFO + ",key=0", "abe", 0.0)
    posts = shore.on_ping(ABE_INFO.replace("9201", "9301") + ",key=0", "abe", 3.0)
    assert posts and all(v.endswith("route=localhost:9301") for _, v in posts)
    assert shore.nodes["abe"].index == 1


def test_try_vnode_offers_the_shore_route():
    shore = make_shore(vnode_routes=["10.0.0.7:9200"])
    posts = shore.iterate(0.0)
    assert ("PSHARE_CMD", "cmd=output,src_name=TRY_SHORE_HOST,dest_name=TRY_SHORE_HOST,route=10.0.0.7:9200") in posts
    assert ("TRY_SHORE_HOST", "pshare_route=localhost:9200") in posts


def test_handshake_between_the_two_states():
    """Wire the two state machines together the way the two pShares would."""
    node, shore = make_node(), make_shore()
    node.on_input_summary("localhost:9201", "localhost", 9001, 10.0)
    shore_cmds, node_cmds = [], []
    now = 0.0
    for _ in range(5):
        for key, value in node.iterate(now):
            if key == "PSHARE_CMD":
                node_cmds.append(value)
            elif key == "NODE_BROKER_PING_0":
                shore_cmds += [v for k, v in shore.on_ping(value, "abe", now) if k == "PSHARE_CMD"]
        for key, value in shore.iterate(now):
            if key == "NODE_BROKER_ACK_ABE":
                node_cmds += [v for k, v in node.on_ack(value, "shoreside", now) if k == "PSHARE_CMD"]
        now += 1.0
    assert "cmd=output,src_name=NODE_REPORT_LOCAL,dest_name=NODE_REPORT,route=localhost:9200" in node_cmds
    assert "cmd=output,src_name=DEPLOY_ALL,dest_name=DEPLOY,route=localhost:9201" in shore_cmds
    assert node.acknowledged and list(shore.nodes) == ["abe"]


def test_docs_say_what_the_apps_say():
    """docs/<App>.md carries the app's --example and --interface text verbatim."""
    from pathlib import Path

    from moosdb_py.share import Share
    from oilspill_moos.field.node_broker import NodeBroker
    from oilspill_moos.field.shore_broker import ShoreBroker

    docs = Path(__file__).resolve().parents[2] / "docs"
    for app in (Share, NodeBroker, ShoreBroker):
        page = (docs / f"{app.default_name}.md").read_text()
        assert app.example_config.strip() in page and app.interface.strip() in page, app.default_name


def test_ping_before_the_shore_knows_its_own_record_is_not_a_mismatch():
    shore = ShoreBrokerState("shoreside", bridges=[("DEPLOY_ALL", "DEPLOY")])
    posts = shore.on_ping(ABE_INFO + ",key=0", "abe", 0.0)
    assert shore.nodes["abe"].status == "ok"
    assert ("PSHARE_CMD", "cmd=output,src_name=DEPLOY_ALL,dest_name=DEPLOY,route=localhost:9201") in posts
    assert not any(k.startswith("NODE_BROKER_ACK") for k, _ in shore.iterate(0.5))  # acks wait for the record


def test_node_asks_again_for_bridges_its_pshare_lost():
    node = make_node()
    node.on_output_summary("NODE_BROKER_PING_0->NODE_BROKER_PING:localhost:9200")
    node.on_ack(SHORE_INFO + ",status=ok,key=0,id=1", "shoreside", 10.0)
    node.on_output_summary("NODE_BROKER_PING_0->NODE_BROKER_PING:localhost:9200, "
                           "NODE_REPORT_LOCAL->NODE_REPORT:localhost:9200")
    assert [k for k, _ in node.iterate(16.0) if k == "PSHARE_CMD"] == []  # all there
    node.on_output_summary("")  # pShare restarted and lost them
    assert ("PSHARE_CMD", "cmd=output,src_name=NODE_REPORT_LOCAL,dest_name=NODE_REPORT,route=localhost:9200") \
        in node.iterate(17.0)
    assert [k for k, _ in node.iterate(18.0) if k == "PSHARE_CMD"] == []  # not more often than every 5 s


def test_node_acked_before_its_pshare_had_the_ping_route_asks_for_it():
    """A restarted vehicle can be acked at once by a shore that still remembers it; its pings must still
    get a route, or a shore restarted later never hears from it (seen in the fleet restart test)."""
    node = make_node()
    node.on_ack(SHORE_INFO + ",status=ok,key=0,id=1", "shoreside", 10.0)
    node.on_output_summary("NODE_REPORT_LOCAL->NODE_REPORT:localhost:9200")
    ping_route = ("PSHARE_CMD", "cmd=output,src_name=NODE_BROKER_PING_0,dest_name=NODE_BROKER_PING,route=localhost:9200")
    assert ping_route in node.iterate(11.0)
    node.on_output_summary("NODE_BROKER_PING_0->NODE_BROKER_PING:localhost:9200, "
                           "NODE_REPORT_LOCAL->NODE_REPORT:localhost:9200")
    assert ping_route not in node.iterate(20.0)
