"""Safety properties of ``robot.Arm`` under any calibration, any command, any motor parameters
and any backend fault (lost replies, failed sends, lost links with reconnections).

A scripted backend (``ScriptedArm``) stands in for a bus: every ``_read``/``_send``/
``_set_torque`` consults a fault script drawn by hypothesis and may raise. The servo model is
ideal (it is where the last goal that reached it says). The properties:

- every goal reaching the backend is finite, inside the (narrowed) joint limits, and at most
  ``max_step`` from the previous goal that reached the backend (or from the measured pose);
- a failed send does not advance the step bound (the next command is bounded from the last
  goal that really went out);
- NaN, inf, huge values and wrong shapes never reach the backend;
- disconnect turns torque off when it can and always ends disconnected.

Then, on the twin's arm: torque off on leaving the block (exception too), no command without a
connection, torque enabled holding the current pose.
"""

from __future__ import annotations

import contextlib
import logging
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from explore.rigs.motor import ergo_jr_dmp
from plumbing.cli_errors import error
from robot.arm import Arm, JointState, RecoveryPolicy
from robot.errors import BusError, LinkLost, NotConnectedError, SafetyStop
from robot.spec import ArmSpec, JointSpec, ergo_jr_spec
from sim.arm import SimArm

BASE = ergo_jr_spec()


class InjectedFault(BusError):
    """A fault the script raised inside the backend."""


class InjectedLinkLost(LinkLost):
    """A lost link the script raised inside the backend."""


class ScriptedArm(Arm):
    """A backend whose calls fail as a script says.

    Args:
        spec: joint specs.
        start: where the servos are at connect, shape (n,), rad.
        faults: one entry per backend call: 0 ok, 1 raise before anything happens,
            2 (sends only) the goal reaches the servos, then the call raises (a lost status
            reply), 3 the link is lost before anything happens (``LinkLost``: the arm
            reconnects, each reconnection consuming an entry too: 0 back, else still out).
            Exhausted script: no more faults.
    """

    def __init__(self, spec: ArmSpec, start: np.ndarray, faults: list[int]) -> None:
        super().__init__(spec, recovery=RecoveryPolicy(attempts=2, first_delay_s=0.0))
        self.pos = np.asarray(start, dtype=float).copy()
        self.faults = list(faults)
        self.sent: list[np.ndarray] = []  # goals that reached the servos
        self.torque_log: list[bool] = []
        self.backend_torque = True

    def _fault(self) -> int:
        return self.faults.pop(0) if self.faults else 0

    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass

    @property
    def can_reconnect(self) -> bool:
        return True

    def _reconnect(self) -> None:
        if self._fault():
            raise InjectedFault("still unplugged")

    def _read(self) -> JointState:
        f = self._fault()
        if f == 3:
            raise InjectedLinkLost("link lost before a read")
        if f:
            raise InjectedFault("read failed")
        return JointState.from_positions(self.pos.copy(), 0.0)

    def _send(self, positions: np.ndarray) -> None:
        f = self._fault()
        if f == 3:
            raise InjectedLinkLost("link lost before a send")
        if f == 1:
            raise InjectedFault("send failed")
        self.sent.append(np.array(positions, dtype=float))
        self.pos = np.array(positions, dtype=float)
        if f == 2:
            raise InjectedFault("no status packet after the write")

    def _set_torque(self, enabled: bool) -> None:
        if self._fault():
            raise InjectedFault("torque write failed")
        self.backend_torque = enabled
        self.torque_log.append(enabled)


@st.composite
def calibrated_specs(draw) -> ArmSpec:
    """The Ergo Jr with each joint narrowed to any sub-range at least 0.02 rad wide, and any
    max_step from 0.005 to 0.5 rad."""
    lo, hi = [], []
    for j in BASE.joints:
        a = draw(st.floats(j.lower, j.upper - 0.02))
        b = draw(st.floats(a + 0.02, j.upper))
        lo.append(a)
        hi.append(b)
    step = draw(st.floats(0.005, 0.5))
    spec = BASE.with_limits(np.array(lo), np.array(hi))
    return ArmSpec(joints=spec.joints, max_step=step)


nasty = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 1e30, -1e30, math.pi, -math.pi, 0.0]),
)
commands = st.one_of(
    st.lists(nasty, min_size=6, max_size=6),
    st.lists(st.floats(-4, 4), min_size=6, max_size=6),
    st.lists(st.floats(-4, 4), min_size=0, max_size=8),  # wrong shapes too
)
operations = st.lists(
    st.one_of(
        st.tuples(st.just("command"), commands),
        st.tuples(st.just("read"), st.none()),
        st.tuples(st.just("torque"), st.booleans()),
    ),
    min_size=1,
    max_size=40,
)


def _start_inside(draw_fracs: list[float], spec: ArmSpec) -> np.ndarray:
    return spec.lower + np.asarray(draw_fracs) * (spec.upper - spec.lower)


def _drive(arm: ScriptedArm, ops) -> None:
    """Apply ``ops``; every error must be one of the expected kinds."""
    for op, arg in ops:
        try:
            if op == "command":
                out = arm.command(np.asarray(arg, dtype=float))
                np.testing.assert_array_equal(out, arm.sent[-1])  # returns what was sent
            elif op == "read":
                arm.read()
            else:
                arm.set_torque(arg)
        except (InjectedFault, InjectedLinkLost, SafetyStop, ValueError):
            pass


def _check_sent(arm: ScriptedArm, spec: ArmSpec, start: np.ndarray) -> None:
    prev = start
    for s in arm.sent:
        assert np.all(np.isfinite(s))
        assert np.all(s >= spec.lower) and np.all(s <= spec.upper), (s, spec.lower, spec.upper)
        assert np.max(np.abs(s - prev)) <= spec.max_step + 1e-9, (prev, s, spec.max_step)
        prev = s


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    spec=calibrated_specs(),
    fracs=st.lists(st.floats(0, 1), min_size=6, max_size=6),
    ops=operations,
    faults=st.lists(st.sampled_from([0, 0, 0, 0, 1, 2, 3]), max_size=60),
)
def test_no_goal_leaves_the_limits_or_jumps_whatever_the_commands_and_faults(
    spec, fracs, ops, faults
):
    start = _start_inside(fracs, spec)
    arm = ScriptedArm(spec, start, faults=[])
    arm.connect()
    arm.faults = list(faults)  # faults from the first operation on
    _drive(arm, ops)
    _check_sent(arm, spec, start)
    # the step bound is the last goal that went out, never a goal that failed (after a send
    # whose fate is unknown it is re-read from the arm before the next command)
    if arm.sent and not arm._resync_needed:
        np.testing.assert_array_equal(arm.last_sent, arm.sent[-1])
    arm.faults = []
    arm.disconnect()
    assert not arm.is_connected and arm.backend_torque is False


def test_a_failed_send_keeps_the_step_bound_at_the_last_goal_sent():
    spec = ArmSpec(joints=BASE.joints, max_step=0.1)
    arm = ScriptedArm(spec, np.zeros(6), faults=[])
    arm.connect()
    arm.command(np.full(6, 1.0))  # goes to 0.1
    arm.faults = [1]
    with pytest.raises(InjectedFault):
        arm.command(np.full(6, 1.0))  # would have gone to 0.2: failed
    np.testing.assert_allclose(arm.last_sent, 0.1)
    np.testing.assert_allclose(arm.command(np.full(6, 1.0)), 0.2)  # not 0.3


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_commands_never_reach_the_backend(bad):
    arm = ScriptedArm(BASE, np.zeros(6), faults=[])
    arm.connect()
    cmd = np.zeros(6)
    cmd[3] = bad
    with pytest.raises(ValueError, match="non-finite"):
        arm.command(cmd)
    assert arm.sent == []


@settings(max_examples=150, deadline=None)
@given(
    fracs=st.lists(st.floats(0.2, 0.8), min_size=6, max_size=6),
    targets=st.lists(st.lists(st.floats(-3, 3), min_size=6, max_size=6), min_size=2, max_size=6),
    faults=st.lists(st.sampled_from([0, 2]), min_size=1, max_size=6),
)
def test_a_lost_status_reply_does_not_let_the_next_goal_jump(fracs, targets, faults):
    spec = ArmSpec(joints=BASE.joints, max_step=0.1)
    start = _start_inside(fracs, spec)
    arm = ScriptedArm(spec, start, faults=[])
    arm.connect()
    arm.faults = list(faults)
    for t in targets:
        with contextlib.suppress(InjectedFault):
            arm.command(np.asarray(t))
    _check_sent(arm, spec, start)


def test_an_arm_outside_its_calibrated_limits_returns_at_most_max_step_per_tick():
    spec = BASE.with_limits(np.full(6, -0.5), np.full(6, 0.5))
    arm = ScriptedArm(spec, np.full(6, 1.0), faults=[])  # moved by hand past the limit
    arm.connect()
    path = [arm.command(np.zeros(6)) for _ in range(12)]
    steps = np.abs(np.diff(np.vstack([np.full(6, 1.0), *path]), axis=0)).max(axis=1)
    assert steps.max() <= spec.max_step + 1e-9, steps
    # 1.0 -> 0.85 -> 0.70 -> 0.55 (outside, closer each tick) -> 0.40: inside from the 4th
    # tick on, never out again, and at the target in the end
    np.testing.assert_allclose(path[2], 0.55)
    assert all(np.all(p <= 0.5) for p in path[3:])
    np.testing.assert_allclose(path[-1], 0.0)


def test_enabling_torque_outside_the_limits_holds_the_pose_within_one_step():
    spec = BASE.with_limits(np.full(6, -0.5), np.full(6, 0.5))
    arm = ScriptedArm(spec, np.full(6, -0.9), faults=[])
    arm.connect()
    arm.set_torque(True)
    np.testing.assert_allclose(arm.sent[-1], -0.9 + spec.max_step)  # not -0.5 at once


@settings(max_examples=200, deadline=None)
@given(
    spec=calibrated_specs(),
    start=st.lists(st.floats(-2.7, 2.7), min_size=6, max_size=6),
    targets=st.lists(st.lists(st.floats(-4, 4), min_size=6, max_size=6), min_size=1, max_size=30),
)
def test_from_anywhere_every_step_is_bounded_and_an_arm_once_inside_stays_inside(
    spec, start, targets
):
    prev = np.asarray(start)
    inside = (prev >= spec.lower) & (prev <= spec.upper)
    for t in targets:
        out = spec.clamp(np.asarray(t), prev)
        assert np.max(np.abs(out - prev)) <= spec.max_step + 1e-9
        # a joint inside stays inside; one outside never moves further out
        ok = (out >= spec.lower) & (out <= spec.upper)
        assert np.all(ok[inside])
        dist_prev = np.maximum(spec.lower - prev, 0) + np.maximum(prev - spec.upper, 0)
        dist_out = np.maximum(spec.lower - out, 0) + np.maximum(out - spec.upper, 0)
        assert np.all(dist_out <= dist_prev + 1e-12)
        inside |= ok
        prev = out


def test_disconnect_never_raises_even_when_closing_the_link_fails():
    arm = ScriptedArm(BASE, np.zeros(6), faults=[])
    arm.connect()

    def boom() -> None:
        raise InjectedFault("port vanished")

    arm._disconnect = boom  # type: ignore[method-assign]
    arm.disconnect()
    assert not arm.is_connected


def test_disconnect_closes_the_link_even_when_torque_off_fails():
    arm = ScriptedArm(BASE, np.zeros(6), faults=[])
    arm.connect()
    arm.set_torque(True)
    arm.faults = [1]  # the torque-off write fails
    arm.disconnect()
    assert not arm.is_connected


def test_a_torque_off_failing_under_an_exception_is_said_on_its_one_error_line(caplog, capsys):
    """The link drops (the exception ending the run), so the torque-off on leaving the block
    fails too: one ``ergo: error:`` line says both, and no log line of the arm repeats it. A
    disconnect with no exception in flight still logs the failure as an error."""
    arm = ScriptedArm(BASE, np.zeros(6), faults=[])
    with caplog.at_level(logging.DEBUG, logger="robot.arm"), pytest.raises(LinkLost) as info:  # noqa: SIM117
        with arm:  # the arm's own exit, inside pytest.raises
            arm.set_torque(True)
            arm.faults = [1]  # the torque-off write on the way out fails
            raise LinkLost("servo(s) 1 did not answer on /dev/pts/9")
    assert not arm.is_connected
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.INFO]
    assert [m for m in said if "torque" in m] == []  # the fault counters' INFO line stays
    assert error(info.value) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("ergo: error: servo(s) 1 did not answer on /dev/pts/9; ")
    assert "could not turn torque off on disconnect: torque write failed" in lines[0]

    caplog.clear()
    arm = ScriptedArm(BASE, np.zeros(6), faults=[])
    arm.connect()
    arm.set_torque(True)
    arm.faults = [1]
    with caplog.at_level(logging.ERROR, logger="robot.arm"):
        arm.disconnect()
    assert [r.getMessage() for r in caplog.records] == [
        "could not turn torque off on disconnect: torque write failed"
    ]


@settings(max_examples=60, deadline=None)
@given(
    spec=calibrated_specs(),
    fracs=st.lists(st.floats(0, 1), min_size=6, max_size=6),
    theta=st.lists(st.floats(-1, 1), min_size=48, max_size=48),
    faults=st.lists(st.sampled_from([0, 0, 0, 0, 1, 2, 3]), max_size=80),
)
def test_any_motor_parameters_played_through_any_faults_stay_safe(spec, fracs, theta, faults):
    """An episode's movement (the DMP of any theta, at the twin's joint ranges, which are
    wider than a calibration's) played command by command, with faults on the way."""
    start = _start_inside(fracs, spec)
    arm = ScriptedArm(spec, start, faults=[])
    arm.connect()
    arm.faults = list(faults)
    trajectory = ergo_jr_dmp().trajectory(np.asarray(theta))
    _drive(arm, [("command", q) for q in trajectory])
    _check_sent(arm, spec, start)


def test_a_failed_send_while_enabling_torque_rereads_the_step_bound():
    """Regression (found by hypothesis): the goal sent by ``set_torque(True)`` reached the
    servos, then the call failed; the step bound kept the older goal instead of being re-read,
    as ``command`` does after a failed send."""
    spec = ergo_jr_spec()
    start = np.full(6, 0.05)
    arm = ScriptedArm(spec, start, faults=[])
    arm.connect()
    arm.faults = [0, 2]  # the read is fine; the goal goes out, then no status packet
    with pytest.raises(InjectedFault):
        arm.set_torque(True)
    assert arm._resync_needed
    out = arm.command(start + 1.0)  # re-read from the arm: one max_step from where it is
    np.testing.assert_allclose(out, start + spec.max_step)
    np.testing.assert_array_equal(arm.last_sent, arm.sent[-1])
    arm.disconnect()


def test_a_reconnection_that_fails_while_reading_back_keeps_the_step_bound():
    """Regression (found by hypothesis): the link came back but reading the positions back
    failed; the step bound was left empty, and a later command could jump by more than
    ``max_step``."""
    spec = ArmSpec(joints=tuple(JointSpec(f"m{i + 1}", i + 1, -2.0, 1.0, 0.0) for i in range(6)),
                   max_step=0.5)  # fmt: skip
    arm = ScriptedArm(spec, np.zeros(6), faults=[])
    arm.connect()
    arm.command(np.zeros(6))
    # a read loses the link; reconnection 1 fails; reconnection 2 connects but its read-back
    # fails: the arm gives up with a SafetyStop
    arm.faults = [3, 1, 0, 0, 1]
    with pytest.raises(SafetyStop):
        arm.read()
    np.testing.assert_array_equal(arm.last_sent, arm.sent[-1])
    out = arm.command(np.full(6, -2.0))
    np.testing.assert_allclose(out, np.full(6, -0.5))  # one max_step, not the whole way
    arm.faults = []
    arm.disconnect()


# ---- on the twin's arm (a concrete backend) --------------------------------------------------
def test_torque_goes_off_on_exit_and_on_exception(twin):
    with SimArm(twin) as arm:
        arm.set_torque(True)
        assert twin.torque_enabled()
    assert not twin.torque_enabled() and not arm.is_connected

    with pytest.raises(RuntimeError, match="boom"), SimArm(twin) as arm:
        arm.set_torque(True)
        raise RuntimeError("boom")
    assert not twin.torque_enabled()


def test_commands_need_a_connection(twin):
    with pytest.raises(NotConnectedError, match="connect"):
        SimArm(twin).command(np.zeros(6))


def test_enabling_torque_holds_the_current_pose(twin):
    """A limp arm moved by hand must not jump back to its old command when torque returns."""
    with SimArm(twin) as arm:
        arm.set_torque(False)
        twin.data.qpos[twin._qpos_idx[1]] = 0.7  # moved by hand
        twin.step()
        arm.set_torque(True)
        assert arm.last_sent[1] == pytest.approx(twin.joint_positions()[1], abs=1e-6)
