"""Free-running node clocks: each sensor node counts microseconds from its own
boot with its own rate error; the 32-bit counter wraps every 2^32 us (71.6 min)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WRAP_US = 1 << 32


@dataclass(frozen=True)
class NodeClock:
    offset_us: int        # counter value at simulation time 0 (= node age at t = 0), us
    drift_ppm: float      # rate error of the node's oscillator, parts per million

    def unwrapped_us(self, t_s) -> np.ndarray:
        """Counter at true time t_s, not wrapped (int64 us): n = floor(n0 + t * 1e6 * (1 + d))."""
        t = np.asarray(t_s, dtype=float)
        return np.floor(self.offset_us + t * 1e6 * (1.0 + self.drift_ppm * 1e-6)).astype(np.int64)

    def wrapped_us(self, t_s) -> np.ndarray:
        """Counter as the node sends it (uint32)."""
        return self.unwrapped_us(t_s) % WRAP_US

    def true_time_s(self, node_us) -> np.ndarray:
        """Inverse: true time at which the (unwrapped) counter reads node_us."""
        return (np.asarray(node_us, dtype=float) - self.offset_us) / (1e6 * (1.0 + self.drift_ppm * 1e-6))
