"""What a sensor kind of the robot's bus declares (issue 10), so that scenario.py, simulate.py,
crb.py and nodes/__init__.py loop over nodes.KINDS and name none: a kind is its module in
nodes/ (its node, a SensorKind subclass; found there by nodes.KINDS) and its model in
physics/.

A SensorKind declares
- its name: the section of its scenario keys ([bearings]), the options read from them
  (scn.bearings), the record of its measurements in a run's result (res.bearings) and its
  key in the simulator's stats;
- its scenario keys: its node clock's in [clocks] (clock_keys: <prefix>_offset_us and
  <prefix>_drift_ppm with their defaults) and its section's (keys; section_options() reads
  and checks them, errors naming the file, section and key), read into its Options;
- its values of the site file (site_values(): the Site attributes it adds, site.<name>,
  from the keys of its sections as site.py reads them, with its own checks);
- whether a site has it (present(): its node on the bus, its record in the stats);
- its place on the bus (Node.kind_order; on_bus(): its node and the node's status frame);
- its record of the measurements (record: a class with empty(), concat(), select(),
  stats() and t_s) and its events for the bound: the measurements it hands to the bound
  (hand_to_bound(), taken back by bound_events()), when each exists (complete_s()) and
  their rows at each event (bound_rows(), which crb.pcrb_along_path calls);
- its timebase priority (timebase: on a site without ultrasonic beacons the truth's time base
  is the clock of the present kind with the smallest one).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..clocks import NodeClock
from .base import Node
from .node_status import NodeStatus

if TYPE_CHECKING:
    from ..inifile import IniFile
    from ..scenario import Scenario
    from ..site import Site, SiteRead

# the bound's rows of a kind at event k of the true state (8,): d(measurement)/d(state)
# (n, 8) and the variances (n,) of the measurements at that event, or None (crb.pcrb_along_path)
EventRows = Callable[[int, np.ndarray], "tuple[np.ndarray, np.ndarray] | None"]


@dataclass(frozen=True)
class KindOptions:
    """A sensor kind's scenario keys: its node clock ([clocks] <prefix>_offset_us and
    <prefix>_drift_ppm) and, in a kind's subclass, its section's keys."""
    offset_us: int             # the node's counter at t = 0, us
    drift_ppm: float           # its rate error, ppm

    def clock(self) -> NodeClock:
        return NodeClock(self.offset_us, self.drift_ppm)


class SensorKind(Node):
    """A sensor node of a kind added to every robot's receiver ring and wheel encoders, and what
    its kind declares (module docstring)."""
    name: str                              # module docstring
    keys: frozenset[str] = frozenset()     # its scenario section's keys
    clock_keys: tuple[str, int, float]     # [clocks] prefix, default offset (us), drift (ppm)
    Options: type[KindOptions] = KindOptions   # its scenario keys' values (scn.<name>)
    record: type                           # the record of its measurements
    timebase: int | None = None            # None: its clock is never the time base

    # -- scenario keys (scenario.load_scenario) ------------------------------------------------
    @classmethod
    def clock_key_names(cls) -> tuple[str, str]:
        prefix = cls.clock_keys[0]
        return f"{prefix}_offset_us", f"{prefix}_drift_ppm"

    @classmethod
    def options(cls, ini: IniFile, site: Site) -> KindOptions:
        """Its scenario keys read and checked: its node clock's (the counter at t = 0 in
        0..2^40 us, the drift within +-1000 ppm), then its section's (section_options)."""
        (_, offset_us, drift_ppm), (offset_key, drift_key) = cls.clock_keys, cls.clock_key_names()
        return cls.Options(ini.integer("clocks", offset_key, offset_us, minimum=0, maximum=2**40),
                           ini.number("clocks", drift_key, drift_ppm, minimum=-1000,
                                      maximum=1000),
                           **cls.section_options(ini, site))

    @classmethod
    def section_options(cls, ini: IniFile, site: Site) -> dict[str, Any]:
        """Its section's keys read and checked, by their Options field (none here); errors
        name the file, section and key (ini.error)."""
        return {}

    # -- its site values (site.load_site) --------------------------------------------------------
    @classmethod
    def site_values(cls, read: SiteRead) -> dict[str, Any]:
        """Its values of the site file, by the Site attribute that gives each (site.<name>):
        from its sections' keys and items as site.load_site reads and checks them by the schema
        (read.value(), read.items()), with its own checks (errors by read.error() naming the
        file, section and key); on a site without the kind, its empty values (count 0). None
        here."""
        return {}

    @classmethod
    def present(cls, site: Site) -> bool:
        """The site has this kind (its beacons, its sensors)."""
        raise NotImplementedError

    # -- the bus ---------------------------------------------------------------------------------
    @classmethod
    def on_bus(cls, scn: Scenario, placed: list[Node]) -> list[Node]:
        """Its node and the node's status frame, on a site that has the kind."""
        if not cls.present(scn.site):
            return []
        node = cls(scn.kind_options[cls.name].clock(), scn)
        return [node, NodeStatus(node)]

    def __init__(self, clock: NodeClock, scn: Scenario):
        super().__init__(clock)
        self.scn = scn
        self.opts = scn.kind_options[self.name]      # its scenario keys
        self.measured: Any = self.record.empty()     # its record of the last interval
        self._bound_pending: Any = self.record.empty()   # handed to the bound, not taken yet

    # -- the bound (simulate._pcrb) --------------------------------------------------------------
    def hand_to_bound(self, rec) -> None:
        """Measurements of rec the bound takes (bound_events)."""
        self._bound_pending = self.record.concat([self._bound_pending, rec])

    def bound_events(self, until_s: float = math.inf):
        """The measurements handed to the bound at or before until_s and not taken yet (the
        posterior bound's measurement events), in time order; later ones wait for the next
        window."""
        pend = self._bound_pending
        pend = pend.select(np.argsort(pend.t_s, kind="stable"))
        now = pend.t_s <= until_s
        self._bound_pending = pend.select(~now)
        return pend.select(now)

    @classmethod
    def complete_s(cls, scn: Scenario, events) -> np.ndarray:
        """True time by which each of the events' measurements exists, s (simulate's
        _complete_times): here its own instant."""
        return events.t_s

    @classmethod
    def bound_rows(cls, scn: Scenario, events, t_ev: np.ndarray, states: np.ndarray) -> EventRows:
        """Its rows of the bound at each event of t_ev (the distinct instants of every kind's
        events; states: (K, 8) the true state at each, crb.STATE order)."""
        raise NotImplementedError


def by_event(t_ev: np.ndarray, t_s: np.ndarray, rows: list, width: int) -> list[np.ndarray]:
    """rows[i] (of the measurement at true time t_s[i]) gathered by event of t_ev, in their
    order: (n_k, width) for each event k."""
    out: list[list] = [[] for _ in range(len(t_ev))]
    for e, row in zip(np.searchsorted(t_ev, t_s).tolist(), rows):
        out[e].append(row)
    return [np.array(r).reshape(-1, width) for r in out]
