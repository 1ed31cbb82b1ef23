"""Where beaconloc-view's MAVLink comes from: a pymavlink connection (udpin:, udpout:,
tcp:, serial, as mavutil spells them) or a growing file of raw MAVLink bytes (--follow:
`make demo` writes the bridge's stream from the User-Mode Linux guest, which has no
network to the host, into its results folder on the shared file system)."""
from __future__ import annotations

import os
import threading
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402  (MAVLINK20 must be set first)

from ..udp import widen_receive_buffer  # noqa: E402

HEARTBEAT_PERIOD_S = 1.0


class FollowFile:
    """Reads a file of concatenated MAVLink frames as it grows (tail -F: waits for it to
    appear, starts again when it is replaced or truncated)."""

    def __init__(self, path: str):
        self.path = path
        self._fh = None
        self._ino = None
        self._parser = None

    def _reopen(self) -> bool:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        try:
            self._fh = open(self.path, "rb")
        except FileNotFoundError:
            return False
        self._ino = os.fstat(self._fh.fileno()).st_ino
        self._parser = mavutil.mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        return True

    def poll(self) -> list:
        if self._fh is None and not self._reopen():
            return []
        try:
            st = os.stat(self.path)
            if st.st_ino != self._ino or st.st_size < self._fh.tell():
                if not self._reopen():
                    return []
        except FileNotFoundError:
            return []
        data = self._fh.read()
        if not data:
            return []
        msgs = self._parser.parse_buffer(data) or []
        return [m for m in msgs if m.get_type() != "BAD_DATA"]

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()


class Receiver:
    """A thread feeding every message of the source to sink(msg). It says it is idle
    (idle_s) since the last message (or since it started)."""

    def __init__(self, sink, *, endpoint: str | None = None, follow: str | None = None,
                 poll_s: float = 0.02):
        if (endpoint is None) == (follow is None):
            raise ValueError("one of endpoint and follow")
        self.sink = sink
        self.poll_s = poll_s
        self.follow = FollowFile(follow) if follow else None
        self.conn = None
        self.sends_heartbeat = False
        if endpoint:
            self.conn = mavutil.mavlink_connection(endpoint, source_system=255,
                                                   source_component=mavutil.mavlink.MAV_COMP_ID_MISSIONPLANNER)
            # a client of a router's or MAVProxy's udpin/tcp port must speak first to be
            # sent anything (as a ground station does: a HEARTBEAT a second)
            self.sends_heartbeat = endpoint.startswith(("udpout:", "tcp:"))
            if endpoint.startswith(("udpin:", "udpout:", "udp:")):
                # a view the machine holds up for a moment loses no message (udp.py)
                widen_receive_buffer(self.conn.port)
        self.count = 0
        self.last_msg_s = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mavlink-in", daemon=True)

    def start(self) -> "Receiver":
        self._thread.start()
        return self

    def idle_s(self) -> float:
        return time.monotonic() - self.last_msg_s

    def _take(self, msg) -> None:
        self.count += 1
        self.last_msg_s = time.monotonic()
        self.sink(msg)

    def _run(self) -> None:
        next_hb = 0.0
        while not self._stop.is_set():
            if self.follow is not None:
                msgs = self.follow.poll()
                for m in msgs:
                    self._take(m)
                if not msgs:
                    time.sleep(self.poll_s)
                continue
            if self.sends_heartbeat and time.monotonic() >= next_hb:
                next_hb = time.monotonic() + HEARTBEAT_PERIOD_S
                self.conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS,
                                             mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            msg = self.conn.recv_match(blocking=True, timeout=0.2)
            if msg is not None and msg.get_type() != "BAD_DATA":
                self._take(msg)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        if self.conn is not None:
            self.conn.close()
        if self.follow is not None:
            self.follow.close()
