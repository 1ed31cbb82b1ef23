"""The sensor nodes on the bus, one module per node kind (base.Node is what they share).

Every robot has the receiver ring (with ultrasonic beacons) and the wheel encoders, placed
here. The kinds are found, not listed: every Node subclass of a module of this package that
declares its kind_order (KINDS, in that order); a sensor kind with scenario keys, a record
and a share of the bound is a sensor_kind.SensorKind, which scenario.py, simulate.py and
crb.py loop over (sensor_kinds()) without naming one. A new kind is its module here and its
model in physics/ (and its frame in the DBC, its keys in the site schema). Nodes draw their
processing latencies in bus order from one generator, so a kind appended at the end (the
next free kind_order) leaves the frames of the others as they were.

A team of robots (team_sim.py) puts other nodes on its bus, one pair per robot:
range_module.RangeModule (RANGE, the leader's pings) and track_encoders.TrackEncoders
(TRACK_ENCODERS); on_bus() is the single robot's.
"""
from __future__ import annotations

import importlib
import pkgutil
from typing import TYPE_CHECKING

from ..clocks import NodeClock
from ..dbc import node_names
from .base import Interval, Node
from .node_status import NodeStatus
from .receiver_ring import ReceiverRing
from .sensor_kind import KindOptions, SensorKind
from .wheel_encoders import ODOMETRY_COLUMNS, WheelEncoders

if TYPE_CHECKING:
    from ..scenario import Scenario

__all__ = ["Interval", "Node", "NodeStatus", "ReceiverRing", "WheelEncoders", "SensorKind",
           "KindOptions", "ODOMETRY_COLUMNS", "KINDS", "sensor_kinds", "on_bus", "node_ids"]


def _found_kinds() -> tuple[type[Node], ...]:
    """Every Node subclass of this package's modules that declares its kind_order, in that
    order (each module imported)."""
    found = []
    for info in pkgutil.iter_modules(__path__):
        module = importlib.import_module(f"{__name__}.{info.name}")
        found += [obj for obj in vars(module).values()
                  if isinstance(obj, type) and issubclass(obj, Node)
                  and obj.__module__ == module.__name__
                  and vars(obj).get("kind_order") is not None]
    found.sort(key=lambda kind: kind.kind_order)
    orders = [kind.kind_order for kind in found]
    if len(set(orders)) != len(orders):
        raise RuntimeError(f"two node kinds with one kind_order: {found}")
    return tuple(found)


# The node kinds of one robot's bus, in kind_order: a run makes each one's random stream
# (Node.stream) from its child seed (simulate.py) and puts its nodes on the bus (on_bus).
KINDS: tuple[type[Node], ...] = _found_kinds()


def sensor_kinds() -> list[type[SensorKind]]:
    """The sensor kinds of KINDS (scenario keys, record, bound: sensor_kind.SensorKind)."""
    return [kind for kind in KINDS if issubclass(kind, SensorKind)]


def on_bus(scn: Scenario) -> tuple[ReceiverRing, WheelEncoders, list[Node]]:
    """The receiver ring, the wheel encoders and every node in bus order with their clocks:
    the receiver ring and the wheel encoders, their status frames, then each kind's nodes in
    KINDS order (its on_bus: a sensor kind's node and its status frame on a site that has the
    kind, or what else a kind places after them), each appended, so a site without a kind
    has the frames it had before the kind existed.
    A site without ultrasonic beacons has no receiver ring on the bus (its clock still
    exists: nothing reads it there)."""
    ring = ReceiverRing(NodeClock(scn.rx_offset_us, scn.rx_drift_ppm))
    wheels = WheelEncoders(NodeClock(scn.encoder_offset_us, scn.encoder_drift_ppm), scn)
    sensors: list[Node] = [ring, wheels] if scn.site.beacon_count else [wheels]
    nodes = sensors + [NodeStatus(n) for n in sensors]
    for kind in KINDS:
        nodes += kind.on_bus(scn, nodes)
    return ring, wheels, nodes


def node_ids(site) -> dict[int, str]:
    """The NodeIds of the sensor nodes on one robot's bus at this site and their DBC names:
    the receiver ring (with ultrasonic beacons), the wheel encoders, each present kind's node."""
    names = node_names()
    nodes = ([ReceiverRing] if site.beacon_count else []) + [WheelEncoders]
    ids = {node.node_id: names[node.node_id] for node in nodes}
    # a kind whose NodeId the DBC's comment does not name (one registered by a test): its name
    ids.update({kind.node_id: names.get(kind.node_id, kind.name)
                for kind in sensor_kinds() if kind.present(site)})
    return dict(sorted(ids.items()))
