"""uFldMessageHandler: addressing, values, the summary; the app on a real moosdb posting FOO with
the source node as source aux."""
from __future__ import annotations

import asyncio

import pytest
from hypothesis import given, strategies as st

from helpers import async_wait_until, one_app_mission, start_moosdb

from moosdb_py.client import MOOSClient
from oilspill_moos.field.message_handler import Delivery, MessageHandler, MessageInbox
from oilspill_moos.node_message import NodeMessage


@pytest.mark.parametrize("text, delivery", [
    ("src_node=abe,dest_node=ben,var_name=FOO,string_val=bar", Delivery("FOO", "bar", "abe")),
    ("src_node=abe,dest_node=ben,var_name=FOO,double_val=2.5", Delivery("FOO", 2.5, "abe")),
    ('src_node=abe,dest_node=all,var_name=FOO,string_val="x=1, y=2"', Delivery("FOO", "x=1, y=2", "abe")),
    ("src_node=abe,dest_group=red,var_name=FOO,string_val=z", Delivery("FOO", "z", "abe")),
    ("src_node=abe,dest_node=cal,var_name=FOO,string_val=bar", None),      # someone else's
    ("src_node=abe,dest_node=ben,string_val=bar", None),                   # no variable
    ("src_node=abe,dest_node=ben,var_name=FOO,string_val=a,double_val=1", None),
])
def test_messages_for_this_vehicle_are_posted(text, delivery):
    assert MessageInbox("ben").receive(text) == delivery


name = st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,11}", fullmatch=True)
text = st.text(st.characters(blacklist_characters='"', blacklist_categories=("Cs", "Cc")), min_size=1,
               max_size=40).filter(lambda v: v == v.strip() and v)


@given(name, name, name, text)
def test_a_quoted_string_value_reads_back_whole(src, dest, var, value):
    """Commas, equals signs and `#` inside a quoted string_val belong to the value."""
    message = NodeMessage.parse(f'src_node={src},dest_node={dest},var_name={var},string_val="{value}"')
    assert (message.src_node, message.dest_node, message.var_name) == (src, dest, var)
    assert message.value == value and message.length() == max(2, len(value))


def test_strict_addressing_and_the_summary():
    inbox = MessageInbox("ben", strict_addressing=True)
    for text in ("src_node=abe,dest_node=all,var_name=A,string_val=1",
                 "src_node=abe,dest_group=red,var_name=A,string_val=1",
                 "src_node=abe,dest_node=ben,var_name=A,string_val=1",
                 "garbage"):
        inbox.receive(text)
    assert inbox.summary() == "total=4,valid=3,rejected=2"
    assert inbox.problem == "NODE_MESSAGE 'garbage': 'garbage' is not key=value"


def test_the_app_posts_the_message_variable(tmp_path):
    db = start_moosdb("--moos_community", "ben")
    mission = one_app_mission(tmp_path / "ben.moos", db.port, "ben", "uFldMessageHandler", "  AppTick = 10\n")
    app = MessageHandler(mission)
    mail = []
    client = MOOSClient("watch", "127.0.0.1", db.port, on_mail=mail.extend, time_warp=10,
                        on_connect=lambda: [client.register(k) for k in ("FOO", "UMH_SUMMARY_MSGS")])

    async def scenario():
        tasks = [asyncio.create_task(app.run_async()), asyncio.create_task(client.run())]
        try:
            await async_wait_until(lambda: client.connected and app.client.connected, timeout=10)
            await async_wait_until(lambda: [m for m in mail if m.key == "UMH_SUMMARY_MSGS"], timeout=10)
            client.notify("NODE_MESSAGE", "src_node=abe,dest_node=ben,var_name=FOO,double_val=7")
            return await async_wait_until(lambda: [m for m in mail if m.key == "FOO"], timeout=10)
        finally:
            app.stop()
            client.close()
            await asyncio.gather(*tasks)

    try:
        (foo,) = asyncio.run(scenario())
    finally:
        db.stop()
    assert (foo.value, foo.source_aux) == (7.0, "abe")
