"""The sensor nodes on the bus, one module per node kind (base.Node is what they share).

Adding a kind (RANGE, BEARING, SONAR_RING: ids reserved in the DBC) is a new module with
a Node subclass, its frame in the DBC and one line in on_bus(). Nodes draw their
processing latencies in bus order from one generator, so a kind appended at the end
leaves the frames of the others as they were.
"""
from __future__ import annotations

from ..clocks import NodeClock
from ..scenario import Scenario
from .base import Interval, Node
from .node_status import NodeStatus
from .receiver_ring import ReceiverRing
from .wheel_encoders import ODOMETRY_COLUMNS, WheelEncoders

__all__ = ["Interval", "Node", "NodeStatus", "ReceiverRing", "WheelEncoders", "ODOMETRY_COLUMNS",
           "on_bus"]


def on_bus(scn: Scenario) -> tuple[ReceiverRing, WheelEncoders, list[Node]]:
    """The receiver ring, the wheel encoders and every node in bus order (each sensor
    node, then their status frames), with their clocks."""
    ring = ReceiverRing(NodeClock(scn.rx_offset_us, scn.rx_drift_ppm))
    wheels = WheelEncoders(NodeClock(scn.encoder_offset_us, scn.encoder_drift_ppm), scn)
    sensors: list[Node] = [ring, wheels]
    return ring, wheels, sensors + [NodeStatus(n) for n in sensors]
