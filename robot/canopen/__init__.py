"""CANopen CiA 402 servo drives over python-can and the ``canopen`` library.

Modules: ``bus`` (``INTERFACE:CHANNEL`` specs), ``network`` (``DriveNetwork``: the drives'
nodes, SDO, PDO maps, NMT and the SYNC cycle), ``cia402`` (the drive state machine, pure),
``emcy`` (EMCY decoding, pure), ``units`` (rad <-> increments), ``arm`` (``CanArm`` on the
network), ``scan`` (``ergo bus scan --can``). ``ergo_drive.eds`` is the EDS of the emulated drives.
Heavy imports (python-can, canopen) happen inside these modules, not here.
"""
