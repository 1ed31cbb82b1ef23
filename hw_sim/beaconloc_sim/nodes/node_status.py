"""NODE_STATUS: the health frame every sensor node sends at 1 Hz of its own clock, at
its own phase, with its own rolling counter (one NodeStatus per node on the bus)."""
from __future__ import annotations

import numpy as np

from ..dbc import signal_modulo
from .base import Interval, Node

PERIOD_US = 1_000_000
FLAG_CLOCK_RESTARTED = 0x2     # DBC NODE_STATUS Flags bit 1
RESTARTED_FLAG_S = 10          # the flag stays on this long after a restart, s


class NodeStatus(Node):
    message = "NODE_STATUS"
    kind_order = 2       # one per node, placed with its node (nodes.on_bus, SensorKind.on_bus)

    def __init__(self, host: Node):
        super().__init__(host.clock)
        self.host = host
        self.node_id = host.node_id
        self.uptime_modulo = signal_modulo(self.message, "Uptime")

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        st_us = self.periodic_us(iv, PERIOD_US, self.host.status_phase_us)
        t_st = self.clock.true_time_s(st_us)
        lat = iv.latency_s(len(t_st))
        sent = np.flatnonzero(~self.host.silent(t_st))
        flags = self.host.status_flags(t_st[sent])
        signals = [{"NodeId": self.node_id, "Flags": int(f),
                    "Uptime": int(st_us[i] // PERIOD_US) % self.uptime_modulo,
                    "TxErrorCount": 0, "RxErrorCount": 0, "Overruns": 0}
                   for i, f in zip(sent.tolist(), flags.tolist())]
        return t_st[sent] + lat[sent], signals

    def restarted(self, sig: dict, since_boot_us: int, epoch: int) -> None:
        """Uptime from the restart, and the clock-restarted flag for its first seconds."""
        sig["Uptime"] = (since_boot_us // PERIOD_US) % self.uptime_modulo
        if since_boot_us < RESTARTED_FLAG_S * PERIOD_US:
            sig["Flags"] |= FLAG_CLOCK_RESTARTED
