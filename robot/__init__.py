"""Hardware abstraction: the ``Arm`` interface (``arm``), joint specs (``spec``), the
watchdog (``watchdog``), torque off on signals (``signals``), the bus lock an emergency preempts
(``bus_guard``), the bus flags (``bus_flags``), lazy name tables (``registry``), a
fault-injecting arm (``faulty_arm``), and the Dynamixel and CANopen backends. Imports no
other package of the project."""

from robot.arm import Arm, ArmCounters, JointState, RecoveryPolicy
from robot.errors import BusError, LinkLost, NotConnectedError, RobotError, SafetyStop
from robot.signals import torque_off_on_signals
from robot.spec import ArmSpec, JointSpec, ergo_jr_spec
from robot.watchdog import Watchdog

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
