"""The receiver-array node: one PULSE_DETECTION frame per detected burst per receiver
(the detections themselves are physics.pulses'), timed on the node's own clock."""
from __future__ import annotations

import numpy as np

from ..clocks import NodeClock
from ..dbc import database
from ..physics.pulses import RECEIVER_NODE_ID
from .base import Interval, Node


class ReceiverRing(Node):
    message = "PULSE_DETECTION"
    node_id = RECEIVER_NODE_ID
    kind_order = 0
    status_phase_us = 250_000

    def __init__(self, clock: NodeClock):
        super().__init__(clock)
        width = database().get_message_by_name(self.message).get_signal_by_name("Width")
        self.width_step_us, self.width_max_us = int(width.scale), int(width.maximum)
        # detections of the last second (status flags look back 1 s), from the previous interval
        self._recent_edges_s, self._recent_saturated = np.zeros(0), np.zeros(0, dtype=bool)
        self._edges_s, self._saturated = self._recent_edges_s, self._recent_saturated

    def sample(self, iv: Interval) -> tuple[np.ndarray, list[dict]]:
        """A frame once the double-pulse window after the leading edge has passed (the node
        decides on DoublePulse then) and the node's processing time."""
        det, scn = iv.detections, iv.scn
        window_s = scn.site.double_pulse_spacing_s + scn.double_pulse_tolerance_s
        lat = iv.latency_s(len(det.edge_s))
        node_us = self.clock.wrapped_us(det.edge_s)
        step = self.width_step_us
        signals = [{"NodeTime": int(node_us[i]), "Receiver": int(det.receiver[i]),
                    "DoublePulse": int(det.double[i]),
                    "Amplitude": int(round(det.amplitude_mv[i])),
                    "Width": step * int(round(min(max(det.width_s[i], 0.0),
                                                  self.width_max_us / 1e6) * 1e6 / step))}
                   for i in range(len(det.edge_s))]
        # the saturation flag of NODE_STATUS looks back 1 s, into the previous interval
        self._edges_s = np.concatenate([self._recent_edges_s, det.edge_s])
        self._saturated = np.concatenate([self._recent_saturated, det.saturated])
        keep = det.edge_s > iv.t_b - 1.0
        self._recent_edges_s, self._recent_saturated = det.edge_s[keep], det.saturated[keep]
        return det.edge_s + window_s + lat, signals

    def status_flags(self, t_s: np.ndarray) -> np.ndarray:
        """Bit 0: a saturated detection in the second before."""
        flags = np.zeros(len(t_s), dtype=np.int64)
        for i, t in enumerate(np.asarray(t_s).tolist()):
            recent = (self._edges_s > t - 1.0) & (self._edges_s <= t)
            flags[i] |= 1 if np.any(self._saturated[recent]) else 0
        return flags
