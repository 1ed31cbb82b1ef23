"""The node kinds of a robot's bus are found, not listed (issue 10): each declares its scenario
section, its place on the bus, its record, its events and rows for the bound and its timebase
priority itself (nodes.sensor_kind.SensorKind), and its values of the site file, and
scenario.py, simulate.py, crb.py, site.py and nodes/__init__.py loop over nodes.KINDS. A toy
kind registered here, in a test, gets its site value, its scenario section, its frames on the
bus, its record and its rows in the bound without an edit anywhere else."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from beaconloc_sim import crb, nodes, outputs, simulate
from beaconloc_sim.dbc import FrameSpec
from beaconloc_sim.inifile import ConfigError
from beaconloc_sim.nodes import KindOptions, SensorKind
from beaconloc_sim.resources import builtin_site_path
from beaconloc_sim.scenario import load_scenario
from beaconloc_sim.site import load_site
from beaconloc_sim.site_schema import load_schema

PACKAGE = Path(simulate.__file__).parent
BASE = (nodes.ReceiverRing, nodes.WheelEncoders, nodes.NodeStatus)   # every robot's, named
# the site file's sections every site has (site.Site's fields), and the ones site.py skips
CORE_SECTIONS = ("site", "beacons", "beaconN", "receivers", "robot", "noise", "team", "tuning",
                 "bridge")


def test_the_kinds_are_found_in_their_modules():
    """KINDS: every robot's nodes, then the kinds of the package's modules in kind_order (the
    bus order); orders, random streams and names each used once."""
    names = [k.__name__ for k in nodes.KINDS]
    assert names == ["ReceiverRing", "WheelEncoders", "NodeStatus", "BearingSensor",
                     "RangeReceiver", "BeaconSurvey", "SonarRing", "Thermometer"]
    assert [k.name for k in nodes.sensor_kinds()] == ["bearings", "ranges", "sonar", "thermometer"]
    streams = [k.stream for k in nodes.KINDS if k.stream]
    assert len({s[0] for s in streams}) == len({s[1] for s in streams}) == len(streams)
    assert len({k.kind_order for k in nodes.KINDS}) == len(nodes.KINDS)
    # the time base on a site without ultrasonic beacons: bearings, else ranges, else sonar
    # (a thermometer's clock never is)
    timed = [k for k in nodes.sensor_kinds() if k.timebase is not None]
    assert sorted(timed, key=lambda k: k.timebase) == timed
    assert [k.name for k in nodes.sensor_kinds() if k.timebase is None] == ["thermometer"]


def test_no_kind_is_named_outside_its_own_module():
    """scenario.py, simulate.py, crb.py, outputs.py, site.py and nodes/__init__.py name no kind
    beyond every robot's: not its class, its record, its module, its name as a string nor its
    clock keys, and site.py none of its site values nor its sections (a new kind edits none
    of them)."""
    files = {name: (PACKAGE / name).read_text() for name in
             ("scenario.py", "simulate.py", "crb.py", "outputs.py", "site.py",
              "nodes/__init__.py")}
    site = load_site(builtin_site_path("kleeman-lab"))
    assert site.kind_values      # the kinds' values, on a site without them too
    kind_sections = [s.name.removesuffix("N") for s in load_schema().sections
                     if s.name not in CORE_SECTIONS]
    for kind in nodes.KINDS:
        if kind in BASE:
            continue
        words = [kind.__name__, kind.__module__.rsplit(".", 1)[-1]]
        if issubclass(kind, SensorKind):
            words += [kind.record.__name__, f'"{kind.name}"', *kind.clock_key_names()]
        for name, text in files.items():
            for word in words:
                assert not re.search(rf"\b{re.escape(word)}", text), (name, word)
    for word in [*site.kind_values, *kind_sections]:
        assert not re.search(rf"\b{re.escape(word)}", files["site.py"]), word


# -- a toy kind: a compass measuring the heading ------------------------------------------------
DELAY_S = 0.004      # the compass has a heading this long after its instant


@dataclass
class Headings:
    """The compass's record: each heading's true instant and value as sent."""
    t_s: np.ndarray
    heading_rad: np.ndarray

    @staticmethod
    def empty() -> Headings:
        return Headings(np.zeros(0), np.zeros(0))

    @staticmethod
    def concat(parts: list[Headings]) -> Headings:
        return Headings(*(np.concatenate([getattr(p, f) for p in parts])
                          for f in ("t_s", "heading_rad")))

    def select(self, keep) -> Headings:
        return Headings(self.t_s[keep], self.heading_rad[keep])

    def stats(self) -> dict:
        return {"measured": int(len(self.t_s))}


class Compass(SensorKind):
    message = "COMPASS"          # not in the DBC: its frame declared here
    node_id = 9
    stream = ("compass", 8)      # the next free child seed
    kind_order = 8               # the next free place: after every kind
    name = "compass"
    keys = frozenset({"sigma_deg", "rate_hz"})
    clock_keys = ("compass", 42_000_000, 10.0)
    record = Headings

    @dataclass(frozen=True)
    class Options(KindOptions):
        sigma_rad: float = math.radians(1.0)
        rate_hz: float = 5.0

    @classmethod
    def frame_spec(cls) -> FrameSpec:
        return FrameSpec(cls.message, 0x7F0, 16)

    @classmethod
    def section_options(cls, ini, site) -> dict:
        return dict(sigma_rad=math.radians(ini.number("compass", "sigma_deg", 1.0, positive=True)),
                    rate_hz=ini.number("compass", "rate_hz", 5.0, positive=True, maximum=100))

    @classmethod
    def site_values(cls, read) -> dict:
        """The compass sits half a wheel base ahead of the wheels' centre."""
        return {"compass_ahead_m": read.value("robot", "wheel_base_m") / 2}

    @classmethod
    def present(cls, site) -> bool:
        return True

    def sample(self, iv):
        node_us = self.periodic_us(iv, int(round(1e6 / self.opts.rate_hz)))
        t = self.clock.true_time_s(node_us)
        noise = iv.rng(self).standard_normal(len(t)) * self.opts.sigma_rad
        rec = Headings(t, self.scn.trajectory.state(t)["theta_rad"] + noise)
        self.measured = rec
        self.hand_to_bound(rec)
        signals = [{"NodeTime": int(u % 2**32), "Heading": float(h)}
                   for u, h in zip(node_us.tolist(), rec.heading_rad.tolist())]
        return t + DELAY_S + iv.latency_s(len(t)), signals

    @classmethod
    def complete_s(cls, scn, events: Headings) -> np.ndarray:
        return events.t_s + DELAY_S

    @classmethod
    def bound_rows(cls, scn, events: Headings, t_ev, states):
        """d(heading)/d(theta) = 1, variance sigma^2."""
        count = np.bincount(np.searchsorted(t_ev, events.t_s), minlength=len(t_ev))
        var = scn.compass.sigma_rad ** 2

        def rows(k, state):
            return crb.embed(np.ones((count[k], 1)), (crb.ITH,)), np.full(count[k], var)
        return rows


BODY = "duration_s = 10\n[path]\nstart = 3.0, 2.0, 0\nsegment1 = straight 2\nsegment2 = turn 90\n"


def test_a_kind_registered_in_a_test_needs_no_other_edit(make_scenario, monkeypatch):
    scn_path = make_scenario(BODY + "[compass]\nsigma_deg = 0.5\n"
                                    "[clocks]\ncompass_drift_ppm = -5\n")
    # not registered: its clock key and its section are unknown
    with pytest.raises(ConfigError, match=r"\[clocks\] compass_drift_ppm: unknown key"):
        load_scenario(str(scn_path))
    with pytest.raises(ConfigError, match=r"\[compass\]: unknown section"):
        load_scenario(str(make_scenario(BODY + "[compass]\nsigma_deg = 0.5\n")))
    plain = simulate.run(load_scenario(str(make_scenario(BODY))), encode=False)

    with pytest.raises(AttributeError, match="compass_ahead_m"):
        load_site(builtin_site_path("kleeman-lab")).compass_ahead_m
    monkeypatch.setattr(nodes, "KINDS", (*nodes.KINDS, Compass))
    # its scenario section and clock keys, read and checked by the kind
    scn = load_scenario(str(scn_path))
    # its site value, from the site's keys as load_site read them
    assert scn.site.compass_ahead_m == scn.site.wheel_base_m / 2 > 0
    assert scn.site.attributes()["compass_ahead_m"] == scn.site.compass_ahead_m
    assert scn.compass == Compass.Options(42_000_000, -5.0, math.radians(0.5), 5.0)
    bad = make_scenario(BODY + "[compass]\nrate_hz = 500\n", name="bad")
    with pytest.raises(ConfigError,
                       match=r"^bad.scenario.ini:\d+: \[compass\] rate_hz: must be <= 100"):
        load_scenario(str(bad))
    with pytest.raises(ConfigError, match=r"\[compass\] heading: unknown key"):
        load_scenario(str(make_scenario(BODY + "[compass]\nheading = 1\n")))
    res = simulate.run(scn, encode=False)

    # on the bus after every other node, with its status frame: a frame per 0.2 s of its
    # clock, the others' frames as they were (their draws too: its stream is its own)
    ids = res.frames.arb_id
    assert np.sum(ids == 0x7F0) == 50
    status = [s["NodeId"] for s, i in zip(res.frames.signals, ids) if i == simulate.ID_STATUS]
    assert status.count(9) == 10

    def others(r) -> dict:
        """The other nodes' frames: each node's signals in its order."""
        out: dict = {}
        for i, sig in zip(r.frames.arb_id.tolist(), r.frames.signals):
            if i != 0x7F0 and sig.get("NodeId") != 9:
                out.setdefault((i, sig.get("NodeId")), []).append(sig)
        return out
    assert others(res) == others(plain)
    assert np.array_equal(plain.firings.t_s, res.firings.t_s)

    # its record and its stats
    assert res.compass.stats() == {"measured": 50}
    assert list(res.measured()) == ["compass"]
    assert outputs.run_stats(res, wall_time_s=0.0)["compass"] == {"measured": 50}

    # its events in the bound, complete DELAY_S after their instant, and its rows: the
    # heading's bound after a heading is below the heading's own variance, and below the
    # bound without the compass
    compass_only = ~np.isin(res.pcrb_t_s, res.firings.t_s)
    assert np.sum(compass_only) == 50 - np.sum(np.isin(res.compass.t_s, res.firings.t_s))
    np.testing.assert_allclose(res.pcrb_complete_s[compass_only],
                               res.pcrb_t_s[compass_only] + DELAY_S)
    heading_var = res.pcrb_cov[compass_only, crb.ITH, crb.ITH]
    assert np.all(heading_var <= math.radians(0.5) ** 2)
    assert plain.pcrb_cov[-1, crb.ITH, crb.ITH] > 2 * res.pcrb_cov[-1, crb.ITH, crb.ITH]
