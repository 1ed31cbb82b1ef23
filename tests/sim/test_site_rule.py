"""The site-validity rule (issue 10): a site needs beacons of a kind that can start the filter,
declared once in the site schema (its sections' starts_alone clauses), generated into the
bridge (config.c config_site_starts, SITE_STARTS_ALONE) and applied by the simulator's
load_site with the same words. tests/bridge/test_site_rule.c checks the library against it."""
from __future__ import annotations

import re

import pytest

from beaconloc_sim.inifile import ConfigError
from beaconloc_sim.site import load_site
from beaconloc_sim.site_schema import Condition, c_header, load_schema, parse_schema

from conftest import SITE_TEXT

SCHEMA = load_schema()


def _value(counts: dict[str, int]):
    return lambda c: counts.get(c.section, 0)


def test_the_rule_is_the_bridges_conditions():
    """[beacons] count >= 1, >= 3 bearing or range beacons, a sonar ring with its map
    (config_is_sonar) or a team site (config_is_team: robots > 0)."""
    assert SCHEMA.site_rule() == [
        (Condition("beacons", "count", 1),),
        (Condition("bearing_beacons", "count", 3),),
        (Condition("range_beacons", "count", 3),),
        (Condition("sonar_ring", "count", 1), Condition("map", "walls", 1)),
        (Condition("team", "robots", 1),)]
    header = c_header(SCHEMA)
    assert "X(3, sonar_ring, count, sonar_ring.count, 1)" in header
    assert "X(3, map, walls, map.walls, 1)" in header
    assert "#define SITE_STARTS_ALONE_CLAUSES 5" in header


@pytest.mark.parametrize("counts, starts", [
    ({}, False), ({"beacons": 1}, True), ({"bearing_beacons": 2, "range_beacons": 2}, False),
    ({"bearing_beacons": 3}, True), ({"range_beacons": 3}, True),
    ({"sonar_ring": 8}, False), ({"map": 4}, False), ({"sonar_ring": 1, "map": 1}, True),
    ({"team": 1}, True)])
def test_a_site_starts_with_one_clause(counts, starts):
    assert (SCHEMA.site_rule_error(_value(counts)) is None) == starts


def test_the_message_lists_every_way_out_with_its_value():
    """The bridge's words (tests/bridge/test_site_rule.c asserts the same text from C)."""
    counts = {"bearing_beacons": 2, "range_beacons": 1, "sonar_ring": 3}
    assert SCHEMA.site_rule_error(_value(counts)) == (
        "0 allowed only with [bearing_beacons] count >= 3 (now 2), [range_beacons] count >= 3 "
        "(now 1), [sonar_ring] count >= 1 and [map] walls >= 1 (now 3 and 0) or [team] "
        "robots >= 1 (now 0)")
    assert SCHEMA.site_rule_error(_value(counts), given=False) == (
        "not set: the site file must give the beacons: [beacons] count >= 1 (now 0), "
        "[bearing_beacons] count >= 3 (now 2), [range_beacons] count >= 3 (now 1), "
        "[sonar_ring] count >= 1 and [map] walls >= 1 (now 3 and 0) or [team] robots >= 1 "
        "(now 0)")
    # a key the reader does not read ([team] for the simulator): holds only when told
    def value(c: Condition) -> int | None:
        return None if c.section == "team" else 0
    assert SCHEMA.site_rule_error(value).endswith("or [team] robots >= 1 (not simulated)")
    assert SCHEMA.site_rule_error(value, unread_holds=True) is None


_S = '[[section]]\nname = "{name}"\nread_by = ["bridge", "sim"]\n{extra}'
_COUNT = ('[[section.key]]\nname = "count"\ntype = "int"\nunit = ""\ndoc = "n"\n'
          'range = "[0, 8]"\nsim = "required"\n')
_REAL = ('[[section.key]]\nname = "gain"\ntype = "real"\nunit = ""\ndoc = "g"\n'
         'range = "[0, 8]"\ndefault = 1.0\nsim = "optional"\n')


@pytest.mark.parametrize("text, why", [
    (_S.format(name="a", extra="") + _COUNT, "no section declares starts_alone"),
    (_S.format(name="a", extra='starts_alone = ["count > 1"]\n') + _COUNT, "not 'KEY >= N'"),
    (_S.format(name="a", extra='starts_alone = ["number >= 1"]\n') + _COUNT, "no such key"),
    (_S.format(name="a", extra='starts_alone = ["gain >= 1"]\n') + _REAL, "not an int key"),
    (_S.format(name="a", extra='starts_alone = ["count >= 1", "[b] count >= 1"]\n') + _COUNT
     + _S.format(name="b", extra="") + _COUNT, "the first clause is one key"),
    (_S.format(name="a", extra='starts_alone = ["count >= 1"]\n') + _COUNT
     + _S.format(name="aN", extra='indexed_by = "a"\nstarts_alone = ["count >= 1"]\n')
     + _COUNT, "not an int key of a section the bridge reads"),
])
def test_bad_rule_is_refused(text, why):
    with pytest.raises(ValueError, match=why):
        parse_schema(text)


def _zero_beacons(text: str, bearing: int) -> str:
    """kleeman-lab without its ultrasonic beacons, with `bearing` bearing beacons."""
    text = re.sub(r"\[beacon\d+\][^\[]*", "", text)
    text = re.sub(r"(\[beacons\][^\[]*?)count = \d+", r"\g<1>count = 0", text, count=1)
    return text + f"[bearing_beacons]\ncount = {bearing}\n" + "".join(
        f"[bearing_beacon{i}]\nx_m = {i}\ny_m = {i * i % 5}\n" for i in range(1, bearing + 1))


def test_the_simulator_applies_the_rule(tmp_path):
    """load_site refuses what the bridge refuses (one or two bearing beacons alone start
    nothing: the simulator accepted them before the rule was one), with the bridge's words and
    the file, line and key; a team's site (team=True) needs no fixed beacons."""
    path = tmp_path / "two.ini"
    path.write_text(_zero_beacons(SITE_TEXT, 2))
    with pytest.raises(ConfigError) as err:
        load_site(path)
    line = next(i for i, row in enumerate(path.read_text().splitlines(), start=1)
                if row == "count = 0")
    assert str(err.value) == (
        f"two.ini:{line}: [beacons] count: 0 allowed only with [bearing_beacons] count >= 3 "
        "(now 2), [range_beacons] count >= 3 (now 0), [sonar_ring] count >= 1 and [map] "
        "walls >= 1 (now 0 and 0) or [team] robots >= 1 (not simulated)")
    assert load_site(path, team=True).bearing_beacon_count == 2
    path.write_text(_zero_beacons(SITE_TEXT, 3))
    assert load_site(path).bearing_beacon_count == 3
