"""What stops a ``CanArm``: the health of its drives, read from what the network heard
(``robot.canopen.network.DriveNetwork``), as one line, or None while every node is healthy.

A node stops the arm when it sent an EMCY error, when its heartbeat is silent for longer than
the limit (heartbeat time x factor; not while frames wait unread by the host, which is then
behind, nor just after the host itself did not run, nor while the node's TPDOs keep coming
after the serial line garbled lines or the host fell behind, each for at most a few limits) or
says it left NMT OPERATIONAL, when it reports FAULT or QUICK STOP ACTIVE (its own quick-stop
input, or its reaction to losing the host, 0x6007: it no longer follows the host's targets), or
when it answered no SYNC for ``max_position_age_s``.
Reading, and noting when the host found itself behind (``DriveNetwork.behind_at``): the arm's
monitor thread and its calls ask, the arm turns torque off.
"""

from __future__ import annotations

import time

from robot.canopen import emcy
from robot.canopen.cia402 import State
from robot.canopen.network import HEARTBEAT_OPERATIONAL, DriveNetwork, safe_decode

# A heartbeat lost to a garbled SLCAN line while the node's TPDOs keep coming is excused for up
# to this many heartbeat limits (guess: a burst of noise of a few hundred ms; longer is a stop).
GARBLED_HEARTBEAT_GRACE = 3.0
# A heartbeat overdue while frames from the adapter wait unread by this host (the host busy:
# the heartbeat may be among them) is excused for up to this many heartbeat limits (guess, as
# above; measured: on a machine at load 11-15 the host's SLCAN reader was 50-700 bytes behind
# when it called a node lost whose heartbeats had all been written to the adapter on time,
# tests/stress/can_heartbeat.py). Past it the node is lost whatever the host read.
BEHIND_HEARTBEAT_GRACE = 3.0
# The host did not run (its process stalled: a C call holding the GIL, such as loading torch's
# libraries, 0.4 s measured here; the CPU taken by others) when it last asked more than this
# fraction of the heartbeat limit ago, while its monitor asks every sixth of it. The frames
# that came meanwhile may sit with its reader, read from the port but not yet handled (so
# neither the port nor the reader says they wait): for one heartbeat time after the stall, in
# which the reader and every live node are heard, that silence is the host's, not the node's.
# Excused as frames waiting unread are, within ``BEHIND_HEARTBEAT_GRACE`` (chosen: three
# missed checks).
HOST_STALL_FRACTION = 0.5
# The states a node reports that stop the arm, and why in words.
STOPPING_STATES = {
    State.FAULT: "in FAULT",
    State.QUICK_STOP_ACTIVE: (
        "in QUICK STOP ACTIVE (its quick-stop input, or its reaction to losing the host, 0x6007)"
    ),
}


def reason_to_stop(
    net: DriveNetwork,
    heartbeat_s: float,
    heartbeat_factor: float,
    max_position_age_s: float,
    host_stalled: bool = False,
) -> str | None:
    """A one-line reason to stop the arm (``safety stop: ...; torque off``), or None when
    every node is healthy or the nodes were not started yet.

    Args:
        net: the drives' network.
        heartbeat_s: the drives' heartbeat time, s; silent for ``heartbeat_factor`` times it
            is lost.
        heartbeat_factor: see above.
        max_position_age_s: the longest a node may answer no SYNC, s.
        host_stalled: the host itself did not run a moment ago (``HOST_STALL_FRACTION``):
            overdue heartbeats are excused as when frames wait unread.
    """
    if not net.started:
        return None
    behind = host_stalled or reading_behind(net)  # before ``now``: it came before it
    now = time.monotonic()
    limit = heartbeat_factor * heartbeat_s
    if behind:
        net.behind_at = now
    n = len(net.node_ids)
    with net.cond:
        for i in range(n):
            active = net.emcy_active[i]
            if active is not None:
                return f"safety stop: {net.who(i)}: {emcy.describe(*active)}; torque off"
        for i in range(n):
            silent = now - net.heartbeat_at[i]
            unread = behind and silent <= BEHIND_HEARTBEAT_GRACE * limit
            if (
                silent > limit
                and not unread
                and not heartbeat_eaten_by_the_line(net, i, now, limit)
            ):
                return (
                    f"safety stop: {net.who(i)} lost: no heartbeat for {silent:.2f} s "
                    f"(heartbeat time {heartbeat_s:.3f} s x {heartbeat_factor})"
                    f"{net.garbled_note()}; torque off"
                )
            if net.nmt_state[i] != HEARTBEAT_OPERATIONAL:
                return (
                    f"safety stop: {net.who(i)} left NMT OPERATIONAL (heartbeat state "
                    f"{net.nmt_state[i]}); torque off"
                )
        for i in range(n):
            state = safe_decode(net.statusword[i]) if net.rx_seq[i] >= 0 else None
            if state in STOPPING_STATES:
                return (
                    f"safety stop: {net.who(i)} {STOPPING_STATES[state]} (statusword "
                    f"0x{int(net.statusword[i]):04X}); torque off"
                )
            waited = now - net.late_since[i]  # NaN when not waiting
            if waited > max_position_age_s:
                return (
                    f"safety stop: {net.who(i)} answered no SYNC for {waited:.2f} s "
                    f"({net.missed[i]} cycles){net.garbled_note()}; torque off"
                )
    return None


def heartbeat_eaten_by_the_line(net: DriveNetwork, i: int, now: float, limit: float) -> bool:
    """Whether node ``i``'s overdue heartbeat was most likely lost between the SLCAN adapter
    and the host rather than by the node: garbled lines were dropped, or the host was behind
    the adapter (whose buffer then overflows: an adapter, as the emulated one, drops what it
    cannot pass on), since its last heartbeat, and its TPDOs, which only a live node in NMT
    OPERATIONAL sends, kept coming (the last within ``limit``, s). Excused for at most
    ``GARBLED_HEARTBEAT_GRACE`` times ``limit``: past that the node counts as lost whatever the
    line did. (On the CAN wire itself a frame is not lost: the controllers retransmit it; an
    SLCAN line has no checksum, no retransmission and a buffer of its own.) Call under
    ``net.cond``."""
    silent = now - net.heartbeat_at[i]
    return bool(
        silent <= GARBLED_HEARTBEAT_GRACE * limit
        and max(net.garbled_at, net.behind_at) > net.heartbeat_at[i]
        and net.rx_seq[i] >= 0
        and now - net.rx_time[i] <= limit
    )


def reading_behind(net: DriveNetwork) -> bool:
    """Whether frames the adapter delivered wait unread by this host (an SLCAN port's unread
    bytes, a virtual bus's queue): the host, not the bus, is behind. False when the bus cannot
    say (socketcan: the kernel queues the frames); never raises."""
    bus = None if net.network is None else net.network.bus
    try:
        unread = getattr(bus, "unread_bytes", None)
        if unread is not None:
            return unread() > 0
        queue = getattr(bus, "queue", None)  # python-can's virtual bus
        return queue is not None and queue.qsize() > 0
    except Exception:
        return False
