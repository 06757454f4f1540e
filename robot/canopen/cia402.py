"""The CiA 402 drive state machine as data: statusword decoding, controlword commands, and the
drive-side transition function (used by the emulated drives and by the tests).

Pure: no I/O, no python-can. Sources: CiA 402-2 (device profile for drives and motion control),
section "Finite state automaton"; the same tables appear in the ``canopen`` library's
``profiles/p402.py`` (docs/facts.md).

Statusword bits (0x6041): 0 ready to switch on, 1 switched on, 2 operation enabled, 3 fault,
4 voltage enabled, 5 quick stop (0 = active), 6 switch on disabled, 9 remote,
10 target reached, 12 (CSP) drive follows the command value.
Controlword bits (0x6040): 0 switch on, 1 enable voltage, 2 quick stop (0 = active),
3 enable operation, 7 fault reset (rising edge).
"""

from __future__ import annotations

from enum import Enum


class State(Enum):
    """Drive states of the CiA 402 power state machine."""

    NOT_READY_TO_SWITCH_ON = "not ready to switch on"
    SWITCH_ON_DISABLED = "switch on disabled"
    READY_TO_SWITCH_ON = "ready to switch on"
    SWITCHED_ON = "switched on"
    OPERATION_ENABLED = "operation enabled"
    QUICK_STOP_ACTIVE = "quick stop active"
    FAULT_REACTION_ACTIVE = "fault reaction active"
    FAULT = "fault"


# Statusword (mask, value) per state (CiA 402-2, table "State coding").
STATUSWORD_TABLE: dict[State, tuple[int, int]] = {
    State.NOT_READY_TO_SWITCH_ON: (0x4F, 0x00),
    State.SWITCH_ON_DISABLED: (0x4F, 0x40),
    State.READY_TO_SWITCH_ON: (0x6F, 0x21),
    State.SWITCHED_ON: (0x6F, 0x23),
    State.OPERATION_ENABLED: (0x6F, 0x27),
    State.QUICK_STOP_ACTIVE: (0x6F, 0x07),
    State.FAULT_REACTION_ACTIVE: (0x4F, 0x0F),
    State.FAULT: (0x4F, 0x08),
}

# Controlword commands (CiA 402-2, table "Command coding").
CW_DISABLE_VOLTAGE = 0x00
CW_QUICK_STOP = 0x02
CW_SHUTDOWN = 0x06
CW_SWITCH_ON = 0x07  # also "disable operation" from operation enabled
CW_DISABLE_OPERATION = 0x07
CW_ENABLE_OPERATION = 0x0F
CW_FAULT_RESET = 0x80
CW_QUICK_STOP_BIT = 0x04  # bit 2: 0 = quick stop active

# Torque off: "disable voltage" takes a drive out of every state whose power stage is on, in
# one transition (CiA 402-2: 9 from OPERATION ENABLED, 10 from SWITCHED ON, 12 from QUICK STOP
# ACTIVE; 7 from READY TO SWITCH ON), to SWITCH ON DISABLED; elsewhere it is no transition
# (FAULT needs bit 7). "Disable operation" (0x07) would leave a drive in QUICK STOP ACTIVE
# there and one in OPERATION ENABLED in SWITCHED ON, its power stage still on.
CW_TORQUE_OFF = CW_DISABLE_VOLTAGE
# The states whose power stage is on, where the motor may hold torque (CiA 402-2 "State
# coding": switched on = power amplifier ready; operation enabled; quick stop active, holding
# or braking; fault reaction active, braking before FAULT). Torque off is confirmed when a
# drive reports none of them: SWITCH ON DISABLED, READY TO SWITCH ON, NOT READY TO SWITCH ON
# or FAULT.
POWER_STAGE_ON = frozenset(
    {
        State.SWITCHED_ON,
        State.OPERATION_ENABLED,
        State.QUICK_STOP_ACTIVE,
        State.FAULT_REACTION_ACTIVE,
    }
)

# Extra statusword bits the emulated drive sets (CiA 402-2 bit definitions above).
SW_VOLTAGE_ENABLED = 0x0010
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_CSP_FOLLOWING = 0x1000

# States in which the drive is powered (voltage enabled bit set).
_POWERED = {
    State.READY_TO_SWITCH_ON,
    State.SWITCHED_ON,
    State.OPERATION_ENABLED,
    State.QUICK_STOP_ACTIVE,
    State.FAULT_REACTION_ACTIVE,
}


class Cia402Error(ValueError):
    """A statusword matched no state, or no controlword leads where asked."""


def decode_statusword(statusword: int) -> State:
    """The drive state encoded in a statusword (bits outside each mask are ignored).

    Raises:
        Cia402Error: the low bits match no state of the table (a corrupt word).
    """
    for state, (mask, value) in STATUSWORD_TABLE.items():
        if statusword & mask == value:
            return state
    raise Cia402Error(f"statusword 0x{statusword:04X} encodes no CiA 402 state")


def torque_is_off(state: State | None) -> bool:
    """Whether a drive in ``state`` has its power stage off (None, a statusword no state has,
    is not a confirmation)."""
    return state is not None and state not in POWER_STAGE_ON


def encode_statusword(state: State, extra: int = SW_REMOTE) -> int:
    """A statusword a drive in ``state`` reports: the table value, voltage enabled when
    powered, plus ``extra`` bits (remote by default)."""
    _, value = STATUSWORD_TABLE[state]
    return (value | (SW_VOLTAGE_ENABLED if state in _POWERED else 0) | extra) & 0xFFFF


def _command(cw: int) -> str | None:
    """Name the device-control command of a controlword (bits 0-3 and 7), without the fault
    reset edge. None: no command (e.g. reserved combination)."""
    if cw & 0x82 == 0x00:
        return "disable voltage"
    if cw & 0x86 == 0x02:
        return "quick stop"
    if cw & 0x87 == 0x06:
        return "shutdown"
    if cw & 0x8F == 0x07:
        return "switch on"  # = disable operation from operation enabled
    if cw & 0x8F == 0x0F:
        return "enable operation"  # = switch on + enable operation from ready to switch on
    return None


def next_state(state: State, controlword: int, previous_controlword: int = 0) -> State:
    """Drive side: the state after receiving ``controlword`` in ``state``.

    Transitions are numbered as in CiA 402-2. Automatic ones (0, 1, 14) are applied too, so a
    drive that boots in NOT_READY_TO_SWITCH_ON moves to SWITCH_ON_DISABLED on its first
    controlword, and FAULT_REACTION_ACTIVE ends in FAULT. A fault reset needs a rising edge of
    bit 7 (``previous_controlword`` without it).
    """
    if state is State.NOT_READY_TO_SWITCH_ON:
        state = State.SWITCH_ON_DISABLED  # transition 1 (automatic, after self test)
    if state is State.FAULT_REACTION_ACTIVE:
        return State.FAULT  # transition 14 (automatic)
    if state is State.FAULT:
        rising = controlword & CW_FAULT_RESET and not previous_controlword & CW_FAULT_RESET
        return State.SWITCH_ON_DISABLED if rising else State.FAULT  # transition 15
    if controlword & CW_FAULT_RESET:
        return state  # fault reset outside FAULT: no effect (bit 7 has priority over the rest)
    cmd = _command(controlword)
    table: dict[tuple[State, str], State] = {
        (State.SWITCH_ON_DISABLED, "shutdown"): State.READY_TO_SWITCH_ON,  # 2
        (State.READY_TO_SWITCH_ON, "switch on"): State.SWITCHED_ON,  # 3
        (State.READY_TO_SWITCH_ON, "enable operation"): State.OPERATION_ENABLED,  # 3 + 4
        (State.SWITCHED_ON, "enable operation"): State.OPERATION_ENABLED,  # 4
        (State.OPERATION_ENABLED, "switch on"): State.SWITCHED_ON,  # 5
        (State.SWITCHED_ON, "shutdown"): State.READY_TO_SWITCH_ON,  # 6
        (State.READY_TO_SWITCH_ON, "disable voltage"): State.SWITCH_ON_DISABLED,  # 7
        (State.READY_TO_SWITCH_ON, "quick stop"): State.SWITCH_ON_DISABLED,  # 7
        (State.OPERATION_ENABLED, "shutdown"): State.READY_TO_SWITCH_ON,  # 8
        (State.OPERATION_ENABLED, "disable voltage"): State.SWITCH_ON_DISABLED,  # 9
        (State.SWITCHED_ON, "disable voltage"): State.SWITCH_ON_DISABLED,  # 10
        (State.SWITCHED_ON, "quick stop"): State.SWITCH_ON_DISABLED,  # 10
        (State.OPERATION_ENABLED, "quick stop"): State.QUICK_STOP_ACTIVE,  # 11
        (State.QUICK_STOP_ACTIVE, "disable voltage"): State.SWITCH_ON_DISABLED,  # 12
        (State.QUICK_STOP_ACTIVE, "enable operation"): State.OPERATION_ENABLED,  # 16
    }
    if cmd is None:
        return state
    return table.get((state, cmd), state)


def fault(state: State) -> State:
    """Drive side: an error occurred (transition 13): any state goes to FAULT_REACTION_ACTIVE,
    except FAULT itself."""
    return state if state is State.FAULT else State.FAULT_REACTION_ACTIVE


# Order of the states the master walks through when enabling (the "power" ladder).
_LADDER = (
    State.SWITCH_ON_DISABLED,
    State.READY_TO_SWITCH_ON,
    State.SWITCHED_ON,
    State.OPERATION_ENABLED,
)
_UP = {
    State.SWITCH_ON_DISABLED: CW_SHUTDOWN,
    State.READY_TO_SWITCH_ON: CW_SWITCH_ON,
    State.SWITCHED_ON: CW_ENABLE_OPERATION,
}
_DOWN = {
    State.READY_TO_SWITCH_ON: CW_DISABLE_VOLTAGE,
    State.SWITCHED_ON: CW_SHUTDOWN,
    State.OPERATION_ENABLED: CW_DISABLE_OPERATION,
}


def controlword_towards(state: State, target: State, previous_controlword: int = 0) -> int | None:
    """Master side: the next controlword that moves a drive from ``state`` one transition
    towards ``target`` (one of SWITCH_ON_DISABLED, READY_TO_SWITCH_ON, SWITCHED_ON,
    OPERATION_ENABLED).

    Returns None when already there, or when the drive must first finish on its own
    (NOT_READY_TO_SWITCH_ON, FAULT_REACTION_ACTIVE). From FAULT it returns the fault reset,
    or first 0x00 when the previous controlword already had bit 7 set (a reset needs a
    rising edge).

    Raises:
        Cia402Error: ``target`` is not a state a master can ask for.
    """
    if target not in _LADDER:
        raise Cia402Error(f"cannot drive a CiA 402 node to {target.value!r} by controlword")
    if state is target:
        return None
    if state in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE):
        return None
    if state is State.FAULT:
        return CW_DISABLE_VOLTAGE if previous_controlword & CW_FAULT_RESET else CW_FAULT_RESET
    if state is State.QUICK_STOP_ACTIVE:
        return CW_DISABLE_VOLTAGE  # transition 12, then up the ladder
    here, there = _LADDER.index(state), _LADDER.index(target)
    return _UP[state] if there > here else _DOWN[state]
