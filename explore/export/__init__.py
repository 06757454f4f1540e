"""What other tools read or drive: runs exported as a LeRobotDataset v3.0 (``lerobot``, from
``episodes``, with ``video``), and the twin as Gymnasium environments (``gym_env``). Their
libraries (pyarrow and PyAV: the extra ``export``; gymnasium: ``gym``) are imported where they
are used."""
