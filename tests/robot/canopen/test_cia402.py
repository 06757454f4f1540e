"""The CiA 402 state machine (pure): statusword decoding, every transition, fault and fault
reset, and the master's controlword path to each state."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot.canopen import cia402
from robot.canopen.cia402 import State

S = State

# (state, controlword, expected state) for every numbered transition of CiA 402-2.
TRANSITIONS = [
    (S.NOT_READY_TO_SWITCH_ON, 0x00, S.SWITCH_ON_DISABLED),  # 1 (automatic)
    (S.SWITCH_ON_DISABLED, 0x06, S.READY_TO_SWITCH_ON),  # 2 shutdown
    (S.READY_TO_SWITCH_ON, 0x07, S.SWITCHED_ON),  # 3 switch on
    (S.SWITCHED_ON, 0x0F, S.OPERATION_ENABLED),  # 4 enable operation
    (S.OPERATION_ENABLED, 0x07, S.SWITCHED_ON),  # 5 disable operation
    (S.SWITCHED_ON, 0x06, S.READY_TO_SWITCH_ON),  # 6 shutdown
    (S.READY_TO_SWITCH_ON, 0x00, S.SWITCH_ON_DISABLED),  # 7 disable voltage
    (S.READY_TO_SWITCH_ON, 0x02, S.SWITCH_ON_DISABLED),  # 7 quick stop
    (S.OPERATION_ENABLED, 0x06, S.READY_TO_SWITCH_ON),  # 8 shutdown
    (S.OPERATION_ENABLED, 0x00, S.SWITCH_ON_DISABLED),  # 9 disable voltage
    (S.SWITCHED_ON, 0x00, S.SWITCH_ON_DISABLED),  # 10 disable voltage
    (S.SWITCHED_ON, 0x02, S.SWITCH_ON_DISABLED),  # 10 quick stop
    (S.OPERATION_ENABLED, 0x02, S.QUICK_STOP_ACTIVE),  # 11 quick stop
    (S.QUICK_STOP_ACTIVE, 0x00, S.SWITCH_ON_DISABLED),  # 12 disable voltage
    (S.FAULT_REACTION_ACTIVE, 0x00, S.FAULT),  # 14 (automatic)
    (S.QUICK_STOP_ACTIVE, 0x0F, S.OPERATION_ENABLED),  # 16 enable operation
    (S.READY_TO_SWITCH_ON, 0x0F, S.OPERATION_ENABLED),  # 3 + 4
]


@pytest.mark.parametrize(("state", "cw", "expected"), TRANSITIONS)
def test_every_transition(state: State, cw: int, expected: State) -> None:
    assert cia402.next_state(state, cw) is expected


@pytest.mark.parametrize(
    ("state", "cw"),
    [
        (S.SWITCH_ON_DISABLED, 0x07),  # switch on needs ready to switch on first
        (S.SWITCH_ON_DISABLED, 0x0F),
        (S.READY_TO_SWITCH_ON, 0x06),
        (S.SWITCHED_ON, 0x07),
        (S.OPERATION_ENABLED, 0x0F),
        (S.FAULT, 0x0F),
        (S.FAULT, 0x06),
    ],
)
def test_commands_without_a_transition_keep_the_state(state: State, cw: int) -> None:
    assert cia402.next_state(state, cw) is state


@pytest.mark.parametrize("state", [s for s in S if s is not S.FAULT])
def test_fault_from_any_state_ends_in_fault(state: State) -> None:
    reacting = cia402.fault(state)
    assert reacting is S.FAULT_REACTION_ACTIVE  # transition 13
    assert cia402.next_state(reacting, 0x0F) is S.FAULT  # 14, whatever the controlword
    assert cia402.fault(S.FAULT) is S.FAULT


def test_fault_reset_needs_a_rising_edge() -> None:
    assert cia402.next_state(S.FAULT, 0x80, previous_controlword=0x0F) is S.SWITCH_ON_DISABLED
    assert cia402.next_state(S.FAULT, 0x80, previous_controlword=0x80) is S.FAULT  # held high
    assert cia402.next_state(S.FAULT, 0x00, previous_controlword=0x80) is S.FAULT
    # fault reset outside FAULT changes nothing (bit 7 has priority over the command bits)
    assert cia402.next_state(S.OPERATION_ENABLED, 0x8F) is S.OPERATION_ENABLED


@pytest.mark.parametrize("state", list(S))
def test_table_values_decode_to_their_state(state: State) -> None:
    _, value = cia402.STATUSWORD_TABLE[state]
    assert cia402.decode_statusword(value) is state


@given(state=st.sampled_from(list(S)), extra=st.integers(0, 0xFFFF))
def test_encoded_statusword_decodes_whatever_the_other_bits(state: State, extra: int) -> None:
    mask, _ = cia402.STATUSWORD_TABLE[state]
    word = cia402.encode_statusword(state, extra=0)
    noisy = (word & mask) | (extra & ~mask & 0xFFFF)
    assert cia402.decode_statusword(noisy) is state
    assert cia402.decode_statusword(cia402.encode_statusword(state)) is state


def test_undecodable_statusword_is_a_clear_error() -> None:
    with pytest.raises(cia402.Cia402Error, match="0x0001 encodes no CiA 402 state"):
        cia402.decode_statusword(0x0001)


def _walk(state: State, target: State, max_steps: int = 10) -> list[int]:
    """Apply the master's controlwords to the drive's state machine until ``target``."""
    cws, prev = [], 0
    for _ in range(max_steps):
        if state is target:
            return cws
        cw = cia402.controlword_towards(state, target, prev)
        if cw is None:  # the drive finishes on its own (transitions 1 and 14)
            cw = prev
        state = cia402.next_state(state, cw, prev)
        cws.append(cw)
        prev = cw
    raise AssertionError(f"did not reach {target} from {state}: {cws}")


@pytest.mark.parametrize("start", list(S))
@pytest.mark.parametrize(
    "target",
    [S.SWITCH_ON_DISABLED, S.READY_TO_SWITCH_ON, S.SWITCHED_ON, S.OPERATION_ENABLED],
)
def test_master_reaches_every_target_from_every_state(start: State, target: State) -> None:
    _walk(start, target)


def test_enable_sequence_is_shutdown_switch_on_enable() -> None:
    assert _walk(S.SWITCH_ON_DISABLED, S.OPERATION_ENABLED) == [0x06, 0x07, 0x0F]
    assert _walk(S.OPERATION_ENABLED, S.SWITCHED_ON) == [0x07]  # torque off
    assert _walk(S.FAULT, S.OPERATION_ENABLED)[0] == 0x80  # fault reset first


def test_fault_reset_after_a_reset_controlword_sends_a_falling_edge_first() -> None:
    assert cia402.controlword_towards(S.FAULT, S.SWITCH_ON_DISABLED, 0x80) == 0x00
    assert cia402.controlword_towards(S.FAULT, S.SWITCH_ON_DISABLED, 0x00) == 0x80


def test_states_a_master_cannot_ask_for() -> None:
    with pytest.raises(cia402.Cia402Error, match="cannot drive"):
        cia402.controlword_towards(S.SWITCHED_ON, S.FAULT)
    assert cia402.controlword_towards(S.FAULT_REACTION_ACTIVE, S.OPERATION_ENABLED) is None
    assert cia402.controlword_towards(S.OPERATION_ENABLED, S.OPERATION_ENABLED) is None
