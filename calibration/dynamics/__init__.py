"""The twin's servo dynamics identified from an arm: excitation trajectories, the recording
(``recording``), the fit with ``mujoco.sysid`` (``fit``), the twin calibration file it writes
(``dynamics.json``, ``calibration.store``) and the report (``report``). docs/dynamics.md."""
