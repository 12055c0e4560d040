"""``haptic-bus upload``'s commit waits for the gate's verdict, not the 1 s of the other transfers.

A three-axis run's coupled gate took 3-8 s in the judge process on a loaded machine: the client
timed out on the commit ("no SDO answer writing 0x2001:00 within 1 s", exit 1) while the run
adopted the upload.  Here the controller's own object dictionary is served by a canopen LocalNode on
python-can's virtual bus whose commit answers 0.5 s late, 2.5 times the client's SDO timeout of
0.2 s (its SDO server answers a download after the write callback returns): the upload must come
back accepted.  The client's timeout is the caller's (``timeout``); 0.2 s, not the 1 s of the
command line, proves the same: every other answer (the virtual bus, a thread here) comes within ms.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import canopen
import pytest

from drives.bus_config import open_bus
from drives.canopen.link import NOTIFIER_CYCLE
from haptic_bus.errors import DriveTimeout
from haptic_bus.node.controller_node import COMMIT, LAST_RESULT, OBJECT_COUNT, WALL_BASE, controller_dictionary
from haptic_bus.node.upload import upload_walls

NODE = 42
SDO_TIMEOUT = 0.2  # s: the client's timeout for every answer but the commit's
VERDICT_AFTER = 0.5  # s: longer than the client's SDO timeout (canopen sends once), well inside its 30 s wait for a verdict


@contextmanager
def controller_dictionary_served(name: str) -> Iterator[tuple[dict[str, Any], canopen.LocalNode]]:
    """The controller's object dictionary (one object) served as node :data:`NODE` on a private
    virtual bus: the bus's keyword arguments and the node, whose callbacks the test sets."""
    bus: dict[str, Any] = {"interface": "virtual", "channel": f"{name}-{uuid.uuid4().hex}"}
    network = canopen.Network(open_bus(**bus))
    network.NOTIFIER_CYCLE = NOTIFIER_CYCLE  # canopen's 1 s recv block made the disconnect wait up to 1 s
    network.connect()
    try:
        node = network.create_node(NODE, controller_dictionary(["end-stop"]))
        node.sdo[OBJECT_COUNT].raw = 1
        yield bus, node
    finally:
        network.disconnect()


def test_a_commit_answered_after_the_sdo_timeout_is_still_the_upload_accepted() -> None:
    with controller_dictionary_served("upload-wait") as (bus, node):
        node.sdo[LAST_RESULT].raw = "accepted: worst margin 11.09 N s/m"
        committed: list[float] = []

        def on_write(index: int, subindex: int, od: object, data: bytes) -> None:
            if index == COMMIT:
                time.sleep(VERDICT_AFTER)  # the judge at work: the download's answer waits for it
                committed.append(time.monotonic())

        node.add_write_callback(on_write)
        started = time.monotonic()
        verdict = upload_walls(bus, NODE, {0: (1200.0, 9.0)}, timeout=SDO_TIMEOUT)
    assert verdict == "accepted: worst margin 11.09 N s/m"
    assert len(committed) == 1  # one commit: the client neither gave up nor sent it twice
    assert committed[0] - started >= VERDICT_AFTER


def test_a_commit_answered_is_accepted_when_the_verdict_cannot_be_read_any_more() -> None:
    # the run ends between its answer to the commit and the client's read of 0x2002: the node no
    # longer answers (here: answers only after 0.5 s, past the client's 0.2 s)
    with controller_dictionary_served("upload-ended") as (bus, node):
        committed = False

        def on_write(index: int, subindex: int, od: object, data: bytes) -> None:
            nonlocal committed
            committed = committed or index == COMMIT

        def on_read(index: int, subindex: int, od: object) -> object:
            if index == LAST_RESULT and committed:
                time.sleep(VERDICT_AFTER)
            return None  # the dictionary's own value

        node.add_write_callback(on_write)
        node.add_read_callback(on_read)
        verdict = upload_walls(bus, NODE, {0: (1200.0, 9.0)}, timeout=SDO_TIMEOUT)
    assert committed and verdict == "accepted (the run ended before its margin could be read)"


def test_a_wall_write_left_unanswered_names_the_object() -> None:
    # the SDO client knew no object past the controller's count: "0x2100:01 (unknown object)"
    with controller_dictionary_served("upload-silent") as (bus, node):

        def on_write(index: int, subindex: int, od: object, data: bytes) -> None:
            if index == WALL_BASE:
                time.sleep(VERDICT_AFTER)  # longer than the client's 0.2 s: the write goes unanswered

        node.add_write_callback(on_write)
        with pytest.raises(DriveTimeout, match=r"writing 0x2100:01 \(Scene object 0\.Stiffness K \(N/m\)\)"):
            upload_walls(bus, NODE, {0: (1200.0, 9.0)}, timeout=SDO_TIMEOUT)
