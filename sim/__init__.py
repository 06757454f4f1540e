"""The MuJoCo twin of the rig and the bus emulators that put it behind a wire protocol."""

# The twin's render settings (sim.twin.Twin's render_quality): its own, or MuJoCo's defaults.
# Here, not in sim.twin, so that command-line parsers can name them without importing MuJoCo.
RENDER_QUALITIES = ("chosen", "legacy")
