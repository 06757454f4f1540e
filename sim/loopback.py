"""What every server of the twin shares: the one address it listens on and its listen queue.

- ``HOST``: 127.0.0.1, the only address served (the MJPEG camera, the stand-in's hands); the
  project never listens on another interface.
- ``LISTEN_BACKLOG``: how many connections the kernel holds until the server's thread accepts
  them. Python's socketserver default is 5: on 2 loaded cores, while the accepting thread
  waits for the GIL (the twin's render), a sixth client's SYN was dropped and its connection
  came ~1.03 s later, after TCP's first retransmission (Linux's initial RTO is 1 s, RFC 6298).
  128 is Linux's long-standing ``SOMAXCONN`` (the kernel caps it at
  ``net.core.somaxconn``).
"""

from __future__ import annotations

HOST = "127.0.0.1"
LISTEN_BACKLOG = 128
