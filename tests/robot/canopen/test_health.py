"""What stops a ``CanArm`` (``robot.canopen.health``): a heartbeat overdue while frames wait
unread by the host is the host's lateness, not the node's, for at most a few limits; past them,
and whenever the host has read everything, the node is lost; so too just after the host itself
did not run."""

from __future__ import annotations

import time

import numpy as np
import pytest

from robot.canopen import health
from robot.canopen.bus import CanBusSpec
from robot.canopen.config import EDS_PATH
from robot.canopen.network import HEARTBEAT_OPERATIONAL, DriveNetwork

HEARTBEAT_S = 0.2
FACTOR = 1.5
LIMIT = HEARTBEAT_S * FACTOR


@pytest.fixture
def net(monkeypatch) -> DriveNetwork:
    """A started network whose nodes were all heard just now (no bus: the fields only)."""
    n = DriveNetwork(CanBusSpec("virtual", "none"), range(1, 7), [f"m{i}" for i in range(1, 7)],
                     EDS_PATH, 0.3, 0.02)  # fmt: skip
    n.started = True
    n.heartbeat_at[:] = time.monotonic()
    n.nmt_state[:] = HEARTBEAT_OPERATIONAL
    return n


def stop(net: DriveNetwork) -> str | None:
    return health.reason_to_stop(net, HEARTBEAT_S, FACTOR, 0.5)


@pytest.mark.parametrize("silent_limits", [1.2, 2.5])
def test_an_overdue_heartbeat_with_frames_unread_is_not_a_lost_node(
    net, monkeypatch, silent_limits
):
    net.heartbeat_at[2] = time.monotonic() - silent_limits * LIMIT
    monkeypatch.setattr(health, "reading_behind", lambda _net: True)
    assert stop(net) is None
    monkeypatch.setattr(health, "reading_behind", lambda _net: False)  # all read: it is lost
    assert stop(net).startswith("safety stop: node 3 (m3) lost: no heartbeat for")


def test_past_the_grace_the_node_is_lost_whatever_waits_unread(net, monkeypatch):
    net.heartbeat_at[2] = time.monotonic() - (health.BEHIND_HEARTBEAT_GRACE + 0.2) * LIMIT
    monkeypatch.setattr(health, "reading_behind", lambda _net: True)
    assert stop(net).startswith("safety stop: node 3 (m3) lost: no heartbeat for")


def test_what_waits_unread_is_read_from_the_bus():
    class Queue:
        def __init__(self, n: int) -> None:
            self.n = n

        def qsize(self) -> int:
            return self.n

    class Network:
        def __init__(self, bus: object) -> None:
            self.bus = bus

    class Slcan:
        def __init__(self, n: int) -> None:
            self.n = n

        def unread_bytes(self) -> int:
            return self.n

    class Net:
        network = None

    net = Net()

    def virtual(n: int) -> object:
        return type("Virtual", (), {"queue": Queue(n)})()

    cases = [(Slcan(9), True), (Slcan(0), False), (virtual(2), True), (virtual(0), False)]
    for bus, behind in [*cases, (object(), False)]:
        net.network = Network(bus)
        assert health.reading_behind(net) is behind
    net.network = None
    assert health.reading_behind(net) is False
    assert np.isfinite(health.BEHIND_HEARTBEAT_GRACE)


@pytest.mark.parametrize("silent_limits", [1.2, 2.5])
def test_an_overdue_heartbeat_just_after_the_host_stalled_is_not_a_lost_node(
    net, monkeypatch, silent_limits
):
    """The host's process did not run (a C call holding the GIL): the heartbeats may sit with
    its reader, read from the port but not handled, so nothing says they wait unread."""
    monkeypatch.setattr(health, "reading_behind", lambda _net: False)
    net.heartbeat_at[2] = time.monotonic() - silent_limits * LIMIT
    assert health.reason_to_stop(net, HEARTBEAT_S, FACTOR, 0.5, host_stalled=True) is None
    lost = health.reason_to_stop(net, HEARTBEAT_S, FACTOR, 0.5, host_stalled=False)
    assert lost.startswith("safety stop: node 3 (m3) lost: no heartbeat for")


def test_past_the_grace_the_node_is_lost_whatever_the_host_did(net, monkeypatch):
    monkeypatch.setattr(health, "reading_behind", lambda _net: False)
    net.heartbeat_at[2] = time.monotonic() - (health.BEHIND_HEARTBEAT_GRACE + 0.2) * LIMIT
    lost = health.reason_to_stop(net, HEARTBEAT_S, FACTOR, 0.5, host_stalled=True)
    assert lost.startswith("safety stop: node 3 (m3) lost: no heartbeat for")


def test_a_heartbeat_lost_while_the_host_was_behind_is_excused_while_the_node_talks(
    net, monkeypatch
):
    """The host fell behind the adapter (its buffer overflowed and dropped a heartbeat), then
    read everything: the node's TPDOs, which only a live operational node sends, still come,
    so the missing heartbeat is the line's; a node whose TPDOs stopped too is lost."""
    behind = [True]
    monkeypatch.setattr(health, "reading_behind", lambda _net: behind[0])
    now = time.monotonic()
    net.heartbeat_at[2] = now - 0.5 * LIMIT  # heard, then the host fell behind
    net.rx_seq[:] = 1
    net.rx_time[:] = now
    assert stop(net) is None  # behind: noted
    behind[0] = False  # read everything; its next heartbeat had been dropped
    net.heartbeat_at[2] = time.monotonic() - 1.5 * LIMIT
    net.behind_at = net.heartbeat_at[2] + 0.1 * LIMIT
    assert stop(net) is None
    net.rx_time[2] = time.monotonic() - 1.2 * LIMIT  # its TPDOs stopped too: lost
    assert stop(net).startswith("safety stop: node 3 (m3) lost: no heartbeat for")
    net.rx_time[2] = time.monotonic()
    net.heartbeat_at[2] = time.monotonic() - (health.GARBLED_HEARTBEAT_GRACE + 0.2) * LIMIT
    assert stop(net).startswith("safety stop: node 3 (m3) lost: no heartbeat for")
