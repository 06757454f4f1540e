"""Pick an offscreen OpenGL backend before MuJoCo is imported when no display is set, and keep
Mesa's software renderer usable in forked processes."""

from __future__ import annotations

import os


def ensure_headless_gl() -> None:
    """Set ``MUJOCO_GL=egl`` unless the user chose a backend or a display exists."""
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def ensure_fork_safe_software_gl() -> None:
    """Make Mesa's software rasteriser (llvmpipe: EGL, OSMesa or GLX without a GPU) draw in the
    calling thread, unless the user set ``LP_NUM_THREADS``. Call before the first GL context.

    llvmpipe's rasteriser threads start with the first context and do not survive ``fork``: a
    process forked after its parent rendered (Gymnasium's ``AsyncVectorEnv`` by default on
    Linux, after ``check_env`` or an evaluation env) waited forever for them in its first
    ``mjr_makeContext`` (observed: mesa's swrast_dri in ``pthread_cond_wait``; issue 32). With
    no rasteriser threads there is nothing to lose across a fork. Cost measured on the twin's
    overhead renders (2 shared cores, load 5): 64, 128 and 240 px frames took 1.9-2.2, 2.5-3.3
    and 4.5-5.0 ms against 2.0-3.2, 3.6-5.0 and 5.7-6.9 ms threaded: small frames gain nothing
    from the threads. A GPU driver ignores the variable.
    """
    os.environ.setdefault("LP_NUM_THREADS", "0")
