"""Rigs: an Arm + a Camera + a Clock (+ the twin for ground truth), built by name from a table
(``rig.RIGS``): ``sim`` (the MuJoCo twin in-process), ``dynamixel`` (serial bus), ``canopen``
(CAN bus); clocks, ball locators, and the twin's outcome dataset."""
