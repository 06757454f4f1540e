"""The twin behind Dynamixel Protocol 2.0: six emulated XL-320 (``emulator``) and
``ergo twin serve --bus dynamixel`` on a pty (``server``). Mirrors ``robot/dynamixel``."""
