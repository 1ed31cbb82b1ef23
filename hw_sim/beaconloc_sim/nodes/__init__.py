"""The sensor nodes on the bus, one module per node kind (base.Node is what they share).

Adding a kind (RANGE, BEARING, SONAR_RING: ids reserved in the DBC) is a new module with
a Node subclass, its frame in the DBC and one line in on_bus(). Nodes draw their
processing latencies in bus order from one generator, so a kind appended at the end
leaves the frames of the others as they were.

A team of robots (team_sim.py) puts other nodes on its bus, one pair per robot:
range_module.RangeModule (RANGE, the leader's pings) and track_encoders.TrackEncoders
(TRACK_ENCODERS); on_bus() is the single robot's.
"""
from __future__ import annotations

from ..clocks import NodeClock
from ..scenario import Scenario
from .base import Interval, Node
from .beacon_survey import BeaconSurvey, SurveyRanges
from .bearing_sensor import BearingSensor, Bearings
from .node_status import NodeStatus
from .range_receiver import RangeReceiver, Ranges
from .receiver_ring import ReceiverRing
from .sonar_ring import SonarPings, SonarRing
from .wheel_encoders import ODOMETRY_COLUMNS, WheelEncoders

__all__ = ["Interval", "Node", "NodeStatus", "ReceiverRing", "WheelEncoders", "BearingSensor",
           "Bearings", "RangeReceiver", "Ranges", "BeaconSurvey", "SurveyRanges", "SonarRing",
           "SonarPings", "ODOMETRY_COLUMNS", "KINDS", "on_bus"]

# The node kinds of one robot's bus (on_bus): a run makes each one's random stream
# (Node.stream) from its child seed (simulate.py).
KINDS: tuple[type[Node], ...] = (ReceiverRing, WheelEncoders, NodeStatus, BearingSensor,
                                 RangeReceiver, BeaconSurvey, SonarRing)


def on_bus(scn: Scenario) -> tuple[ReceiverRing, WheelEncoders, BearingSensor | None,
                                   RangeReceiver | None, list[Node]]:
    """The receiver ring, the wheel encoders, the bearing sensor (None on a site without
    bearing beacons), the range receiver (None on a site without range beacons) and every
    node in bus order with their clocks: the receiver ring and the wheel encoders, their
    status frames, then the bearing sensor and its status frame, then the range receiver and
    its status frame, then the beacons' self-survey (nodes.beacon_survey, on the range
    receiver's clock) when the scenario's [ranges] survey_s > 0, then the sonar ring and its
    status frame on a site with one ([sonar_ring] count > 0; find it in the list: a
    SonarRing) (each appended, so a site without bearing or range beacons, or a run without
    a survey or a sonar ring, has the frames it had before they existed).
    A site without ultrasonic beacons has no receiver ring on the bus (its clock still
    exists: nothing reads it there)."""
    ring = ReceiverRing(NodeClock(scn.rx_offset_us, scn.rx_drift_ppm))
    wheels = WheelEncoders(NodeClock(scn.encoder_offset_us, scn.encoder_drift_ppm), scn)
    sensors: list[Node] = [ring, wheels] if scn.site.beacon_count else [wheels]
    nodes = sensors + [NodeStatus(n) for n in sensors]
    bearing = None
    if scn.site.bearing_beacon_count:
        bearing = BearingSensor(NodeClock(scn.bearing_offset_us, scn.bearing_drift_ppm), scn)
        nodes += [bearing, NodeStatus(bearing)]
    ranger = None
    if scn.site.range_beacon_count:
        ranger = RangeReceiver(NodeClock(scn.range_offset_us, scn.range_drift_ppm), scn)
        nodes += [ranger, NodeStatus(ranger)]
        if scn.range_survey_s > 0:
            nodes.append(BeaconSurvey(ranger, scn))
    if scn.site.sonar_count:
        sonar = SonarRing(NodeClock(scn.sonar_offset_us, scn.sonar_drift_ppm), scn)
        nodes += [sonar, NodeStatus(sonar)]
    return ring, wheels, bearing, ranger, nodes
