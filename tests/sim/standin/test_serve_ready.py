"""``ergo twin serve`` announces its bus only once the bus answers: a client that asks every
id once, with a short timeout and no retry, right after the bus's line gets every answer (as
the ROBOTIS SDK pings ids 1-6: before, ids 1-4 went unanswered for about 3 s while the camera
started)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from robot.canopen.bus import open_bus
from robot.dynamixel.bus import DynamixelBus, NoStatusError

IDS = range(1, 7)
# One try per id: the ROBOTIS SDK's ping timeout at 1 Mbps was 34 ms (measured); with a margin
# for a busy test machine. The CANopen client's is a third of python canopen's default (0.3 s).
PING_TIMEOUT_S = 0.05
SDO_TIMEOUT_S = 0.1


def _serve(bus: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "explore.cli", "twin", "serve", "--bus", bus],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip
    return proc, proc.stdout.readline().strip()


def _silent_dynamixel(port: str) -> list[int]:
    bus = DynamixelBus(port, retries=0, latency_s=PING_TIMEOUT_S, max_latency_s=PING_TIMEOUT_S)
    bus.open()
    silent = []
    try:
        for i in IDS:
            try:
                bus.ping(i)
            except NoStatusError:
                silent.append(i)
    finally:
        bus.close()
    return silent


def _silent_canopen(port: str) -> list[int]:
    import canopen
    from canopen.sdo import SdoCommunicationError

    network = canopen.Network(open_bus(f"slcan:{port}"))
    network.connect()  # the notifier, on the bus opened above
    silent = []
    try:
        for i in IDS:
            node = network.add_node(i, canopen.ObjectDictionary())
            node.sdo.RESPONSE_TIMEOUT, node.sdo.MAX_RETRIES = SDO_TIMEOUT_S, 0
            try:
                node.sdo.upload(0x1000, 0)  # the device type (CiA 301)
            except SdoCommunicationError:
                silent.append(i)
    finally:
        network.disconnect()
    return silent


@pytest.mark.parametrize(
    ("bus", "prefix", "silent"),
    [
        ("dynamixel", "dynamixel bus on ", _silent_dynamixel),
        ("canopen", "canopen bus (slcan) on ", _silent_canopen),
    ],
)
def test_every_id_answers_right_after_the_bus_line(bus, prefix, silent):
    proc, line = _serve(bus)
    try:
        assert line.startswith(prefix), line
        assert silent(line.removeprefix(prefix)) == []
    finally:
        proc.terminate()
        proc.wait(timeout=30)
