"""What other tools read or drive: runs exported as a LeRobotDataset v3.0 (``lerobot``, from
``episodes``, with ``video``). Its libraries (pyarrow, PyAV) are the optional extra ``export``,
imported where they are used."""
