"""``RigError``: a rig could not be built or connected (one line). Its own module so that the
rig's parts (``ball``, ``hardware``, the rig modules) and ``rig`` itself raise it without
importing one another."""


class RigError(RuntimeError):
    """A rig could not be built or connected."""
