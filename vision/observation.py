"""The observation a representation sees: a square colour image of ``OBSERVATION_SIZE`` pixels.

64 x 64 x 3, the paper's VAE input (docs/facts.md): episodes reduce the overhead frame to it
and the VAE's architecture is built for it. Imports nothing heavy.
"""

OBSERVATION_SIZE = 64  # side, pixels (the paper)
