"""Hardware abstraction: the ``Arm`` interface, joint specs and safety. Imports no other
package of the project."""

from robot.arm import Arm, ArmCounters, JointState, RecoveryPolicy
from robot.errors import BusError, LinkLost, NotConnectedError, RobotError, SafetyStop
from robot.safety import Watchdog, torque_off_on_signals
from robot.spec import ArmSpec, JointSpec, ergo_jr_spec

__all__ = [
    "Arm",
    "ArmCounters",
    "ArmSpec",
    "BusError",
    "JointSpec",
    "JointState",
    "LinkLost",
    "NotConnectedError",
    "RecoveryPolicy",
    "RobotError",
    "SafetyStop",
    "Watchdog",
    "ergo_jr_spec",
    "torque_off_on_signals",
]
