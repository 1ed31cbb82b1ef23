"""beaconloc_sim.udp.widen_receive_buffer, which the view's UDP source and the test
listeners use: the kernel grants the room asked for (as root past net.core.rmem_max), and
a receiver held up while a burst arrives keeps every datagram of it."""
from __future__ import annotations

import os
import socket

from beaconloc_sim.udp import RCVBUF_BYTES, widen_receive_buffer


def test_a_held_up_receiver_keeps_a_burst():
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.bind(("127.0.0.1", 0))
        default = rx.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        granted = widen_receive_buffer(rx)
        assert granted == rx.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        if os.geteuid() == 0:
            assert granted >= RCVBUF_BYTES    # Linux doubles it: 2 x 16 MiB
        assert granted >= default
        # 3000 ODOMETRY-sized datagrams (~1 s of a 20x replay) sent before any is read:
        # the default buffer holds a few hundred of them
        n, payload = 3000, bytes(180)
        for _ in range(n):
            tx.sendto(payload, rx.getsockname())
        rx.setblocking(False)
        got = 0
        while True:
            try:
                rx.recv(2048)
            except BlockingIOError:
                break
            got += 1
        if os.geteuid() == 0:
            assert got == n
    finally:
        rx.close()
        tx.close()
