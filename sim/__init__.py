"""The MuJoCo twin of the rig and the bus emulators that put it behind a wire protocol."""
