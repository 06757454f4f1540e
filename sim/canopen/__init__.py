"""The twin behind CANopen: six emulated CiA 402 drives (``drives``), the SLCAN adapter side
(``slcan``) and ``ergo twin serve --bus canopen`` on a pty (``server``). Mirrors
``robot/canopen``."""
