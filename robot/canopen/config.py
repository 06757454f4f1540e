"""The settings of a ``CanArm`` (``CanArmConfig``), and the ones it takes on the emulator's pty
(``PTY_SETTINGS``, ``config_for``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from robot.canopen.bus import CanBusSpec, is_pty, parse_can_spec

EDS_PATH = Path(__file__).resolve().parent / "ergo_drive.eds"
# Abort connection option codes of 0x6007 (CiA 402-2): what a drive does when it loses the
# host (its heartbeat consumer, 0x1016, timed out).
ABORT_NO_ACTION, ABORT_FAULT, ABORT_DISABLE_VOLTAGE, ABORT_QUICK_STOP = 0, 1, 2, 3


@dataclass(frozen=True)
class CanArmConfig:
    """Settings of a ``CanArm``; defaults are guesses for small servo drives at 1 Mbit/s.

    Attributes:
        node_ids: CANopen node id of each joint's drive (None: the spec's servo ids).
        directions: +1/-1 per joint (drive counts grow with the joint angle or against it).
        offsets: joint angle at drive position 0, per joint, rad.
        heartbeat_ms: producer heartbeat time written to each node's 0x1017, ms (guess: 100 ms
            notices a dead node within 150 ms, at 6 frames per 100 ms of bus load).
        heartbeat_factor: a node is lost when silent for this times its heartbeat time (1.5,
            the brief; CiA 301 leaves the consumer time to the integrator).
        pdo_timeout_s: longest wait for the TPDOs answering a SYNC, s (guess: a 1 Mbit/s bus
            carries the 13 frames of a cycle in about 1.5 ms; an SLCAN pty adds a few ms).
        max_position_age_s: the arm stops when a node has answered no SYNC for this long, s
            (guess: 20 control periods at 40 Hz; the drive itself keeps following its last
            target meanwhile, and a dead node is caught sooner by its heartbeat).
        state_timeout_s: longest time for the drives to reach a CiA 402 state, s (guess: real
            drives take up to a few hundred ms to switch on, e.g. to release a brake; the
            emulator behind a pty on a loaded machine was measured taking over 1 s).
        sdo_timeout_s: SDO response timeout, s (canopen's default is 0.3 s).
        following_error_window: if set, written to 0x6065, rad (None: leave the drive's).
        eds: the drives' EDS (object dictionary).
        master_id: the node id of the host's own heartbeat (COB-ID 0x700 + it), which the
            drives consume; not one of the drives' (127: the highest id, rarely a device's).
        master_heartbeat_ms: how often the host sends its heartbeat, ms (guess: 100, as the
            drives' own).
        consumer_ms: heartbeat consumer time written to each drive's 0x1016 sub 1, ms: a drive
            that hears no heartbeat of the host for this long takes the ``abort_option``
            reaction (guess: 10 host heartbeats; the host's heartbeat thread waits for the GIL,
            which a loaded machine delays by hundreds of ms, docs/canopen.md).
        abort_option: the abort connection option code written to each drive's 0x6007 (CiA
            402-2: 0 no action, 1 fault, 2 disable voltage, 3 quick stop); 2: the power stage
            off at once, the joints limp, as every other stop of the project.
    """

    node_ids: tuple[int, ...] | None = None
    directions: tuple[float, ...] | None = None
    offsets: tuple[float, ...] | None = None
    heartbeat_ms: int = 100
    heartbeat_factor: float = 1.5
    pdo_timeout_s: float = 0.02
    max_position_age_s: float = 0.5
    state_timeout_s: float = 3.0
    sdo_timeout_s: float = 0.3
    following_error_window: float | None = None
    eds: Path = EDS_PATH
    master_id: int = 127
    master_heartbeat_ms: int = 100
    consumer_ms: int = 1000
    abort_option: int = ABORT_DISABLE_VOLTAGE


# The settings of a CanArm on an SLCAN pty, i.e. the emulator of `ergo twin serve --bus
# canopen` (a real adapter is a tty or a network interface, never a pty), where not given:
# - heartbeat 500 ms: the emulator's heartbeats cross several Python threads on a shared
#   machine; gaps over 150 ms were seen with the camera rendering under load, so 100 ms x 1.5
#   stopped `ergo calibrate joints` (measured 2026-12-02; 500 is a guess with margin);
# - SDO timeout 2 s: one SDO of the connect's configuration went unanswered for canopen's
#   0.3 s at load 6-8, and for 1.0 s at load 13-15 (measured with tests/stress/load.py, 2026-12-02).
# - the drives' consumer time of the host's heartbeat 2 s: the emulator reads the host's
#   heartbeat through the same threads; the longest gap it saw at load 8 is in docs/canopen.md.
# None is a safety bound on a real arm, which keeps CanArmConfig's defaults.
PTY_SETTINGS = {"heartbeat_ms": 500, "sdo_timeout_s": 2.0, "consumer_ms": 2000}


def config_for(can: str | CanBusSpec, **given: object) -> CanArmConfig:
    """A ``CanArmConfig`` for the bus ``can``: the fields ``given`` (None values left out),
    the pty's ``PTY_SETTINGS`` where the channel is a pseudo-terminal, else the defaults."""
    spec = can if isinstance(can, CanBusSpec) else parse_can_spec(can, None)
    fields = {k: v for k, v in given.items() if v is not None}
    if spec.interface == "slcan" and is_pty(spec.channel):
        fields = {**PTY_SETTINGS, **fields}
    return CanArmConfig(**fields)  # type: ignore[arg-type]
