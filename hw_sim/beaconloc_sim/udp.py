"""A UDP receiver that is held up for a while (a busy host, a Python process the machine
starves) loses datagrams once the kernel's receive buffer is full: the default, ~200 KiB of
kernel memory, holds a few hundred datagrams, a fraction of a second of a fast replay's
MAVLink. widen_receive_buffer gives it room for seconds (socket(7))."""
from __future__ import annotations

import socket

SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # socket(7); Python may lack the name
RCVBUF_BYTES = 16 << 20


def widen_receive_buffer(sock: socket.socket, nbytes: int = RCVBUF_BYTES) -> int:
    """Ask for an nbytes receive buffer on sock: SO_RCVBUFFORCE (root, past
    net.core.rmem_max), else SO_RCVBUF (capped at rmem_max). Returns what the kernel
    granted, bytes (it doubles the request for its bookkeeping)."""
    for opt in (SO_RCVBUFFORCE, socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, nbytes)
            break
        except OSError:
            continue
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
