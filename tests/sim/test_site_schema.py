"""The site schema (hw_sim/beaconloc_sim/data/site_schema.toml) against what derives from it.

The bridge's C tables are generated from the schema at build time (and checked
by tests/bridge/test_config.c); here: the schema is well formed, the docs' key
table is the schema's, the repo's site files hold only schema keys within
their ranges, and the simulator reads every key the schema gives it.
"""
from __future__ import annotations

import math
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from beaconloc_sim.inifile import ConfigError
from beaconloc_sim.resources import builtin_site_path
from beaconloc_sim.site import load_site
from beaconloc_sim.site_schema import (BEACON_SECTION, DOCS_BEGIN, DOCS_END, PARAMS_BEGIN,
                                       PARAMS_END, SCHEMA_RESOURCE, Range, c_header, docs_table,
                                       load_schema, params_table, parse_schema)

from conftest import SITE_TEXT

REPO = Path(__file__).resolve().parents[2]
SCHEMA = load_schema()


def test_docs_key_table_is_the_schemas():
    """docs/bridge.md carries the generated table: `make docs-site-keys` after a schema change."""
    text = (REPO / "docs" / "bridge.md").read_text(encoding="utf-8")
    begin, end = text.find(DOCS_BEGIN), text.find(DOCS_END)
    assert 0 <= begin < end, "the site-keys markers are missing from docs/bridge.md"
    documented = text[begin:end + len(DOCS_END)]
    assert documented == docs_table(SCHEMA), \
        "docs/bridge.md's site-key table differs from the schema: run `make docs-site-keys`"


def test_docs_param_table_is_the_schemas():
    """docs/mavlink.md carries the generated parameter table: `make docs-site-keys`."""
    text = (REPO / "docs" / "mavlink.md").read_text(encoding="utf-8")
    begin, end = text.find(PARAMS_BEGIN), text.find(PARAMS_END)
    assert 0 <= begin < end, "the mavlink-params markers are missing from docs/mavlink.md"
    assert text[begin:end + len(PARAMS_END)] == params_table(SCHEMA), \
        "docs/mavlink.md's parameter table differs from the schema: run `make docs-site-keys`"


def test_params_fit_mavlink_and_are_in_the_c_header():
    """Each parameter: a unique name of <= 16 characters (PARAM_VALUE param_id), a number the
    bridge reads with its range, one SITE_PARAMS row in index order."""
    params = SCHEMA.params()
    assert len(params) >= 40
    names = [k.param for k in params]
    assert len(set(names)) == len(names) and all(len(n) <= 16 for n in names)
    header = c_header(SCHEMA)
    rows = re.findall(r"    X\(([A-Z][A-Z0-9_]*), ([a-z_]+), ([a-z0-9_]+), (K_[A-Z]+), ", header)
    assert [r[0] for r in rows] == names
    for (name, sec, key, ctype), k in zip(rows, params):
        assert (sec, key) == (k.section, k.name) and ctype in ("K_REAL", "K_INT")
    assert f"#define SITE_PARAM_COUNT {len(params)}" in header


@pytest.mark.parametrize("extra, why", [
    ('range = "(0, 10]"\ndefault = 1.0\nparam = "BCN_PERIOD_TOO_LONG"\n', "parameter name"),
    ('range = "(0, 10]"\ndefault = 1.0\nparam = "bcn_period"\n', "parameter name"),
    ('range = "(0, 10]"\nparam = "BCN_PERIOD"\n', "with a range and a default"),
])
def test_bad_param_is_refused(extra, why):
    with pytest.raises(ValueError, match=why):
        parse_schema(_SECTION + _KEY + extra)


def test_param_declared_twice_is_refused():
    two = _KEY + 'range = "(0, 10]"\ndefault = 1.0\nparam = "BCN_X"\n'
    other = two.replace('name = "period_s"', 'name = "other_s"')
    with pytest.raises(ValueError, match="parameter name declared twice"):
        parse_schema(_SECTION + two + other)


def test_docs_table_has_one_row_per_key():
    rows = [r for r in docs_table(SCHEMA).splitlines() if r.startswith("| ") and "`" in r]
    keys = [re.search(r"\| `([a-z_0-9]+)` \|", r).group(1) for r in rows]
    assert keys == [k.name for k in SCHEMA.keys()]


def test_schema_sections_in_file_order():
    assert [s.name for s in SCHEMA.sections] == [
        "site", "beacons", BEACON_SECTION, "receivers", "bearing_beacons", "bearing_beaconN",
        "bearing_sensor", "range_beacons", "range_beaconN", "range_sensor", "robot", "noise",
        "sonar_ring", "sonarN", "map", "wallN", "thermometer", "team", "tuning", "bridge"]
    assert SCHEMA.sections_phrase("N") == (
        "[site], [beacons], [beacon1]..[beaconN], [receivers], [bearing_beacons], "
        "[bearing_beacon1]..[bearing_beaconN], [bearing_sensor], [range_beacons], "
        "[range_beacon1]..[range_beaconN], [range_sensor], [robot], [noise], [sonar_ring], "
        "[sonar1]..[sonarN], [map], [wall1]..[wallN], [thermometer], [team], [tuning], [bridge]")
    assert "[beacon1]..[beacon16]" in SCHEMA.sections_phrase()
    assert "[bearing_beacon1]..[bearing_beacon15]" in SCHEMA.sections_phrase()
    assert "[sonar1]..[sonar15]" in SCHEMA.sections_phrase()
    assert "[wall1]..[wall64]" in SCHEMA.sections_phrase()   # [map] walls, not count


@pytest.mark.parametrize("header, item", [
    ("beacon1", ("beaconN", 1)), ("Beacon16", ("beaconN", 16)), ("beacon17", ("beaconN", 17)),
    ("bearing_beacon3", ("bearing_beaconN", 3)), ("beacon0", None), ("beacon01", None),
    ("beacons", None), ("beacon", None), ("bearing_beacons", None), ("bearing_beacon", None),
    ("sonar_ring", None), ("sonar3", ("sonarN", 3)), ("wall64", ("wallN", 64)), ("walls", None)])
def test_item_sections_by_header(header, item):
    got = SCHEMA.item_of(header)
    assert (None if got is None else (got[0].name, got[1])) == item


def _ini_keys(path: Path) -> list[tuple[str, str, str]]:
    return _ini_text_keys(path.read_text())


def _ini_text_keys(text: str) -> list[tuple[str, str, str]]:
    section, out = None, []
    for line in text.splitlines():
        line = line.split(";")[0].strip()
        if line.startswith("["):
            section = line.strip("[]")
        elif "=" in line:
            key, value = (p.strip() for p in line.split("=", 1))
            out.append((section, key, value))
    return out


SCENARIO_DIR = builtin_site_path().parent   # the packaged scenarios and their site file


@pytest.mark.parametrize("site", sorted(p.name for p in SCENARIO_DIR.glob("*.ini")
                                        if not p.name.endswith(".scenario.ini")))
def test_repo_site_files_hold_schema_keys_in_range(site):
    for section, key, value in _ini_keys(SCENARIO_DIR / site):
        item = SCHEMA.item_of(section)
        name = item[0].name if item else section
        k = SCHEMA.section(name).key(key)   # KeyError: a key the schema does not know
        if k.numeric:
            for rng in (k.range, k.sim_range):
                assert rng is None or rng.contains(float(value)), (section, key, value, rng)


@pytest.mark.parametrize("text, why", [
    ("(0, 1]", None), ("[1, 16]", None), ("[0, inf)", None), ("(-inf, inf)", None),
    ("0..1", "not an interval"), ("[2, 1]", "empty interval"),
])
def test_range_notation(text, why):
    if why:
        with pytest.raises(ValueError, match=why):
            Range.parse(text)
    else:
        r = Range.parse(text)
        assert str(Range.parse(str(r).replace("∞", "inf"))) == str(r)


def test_range_bounds():
    r = Range.parse("(0, 1]")
    assert not r.contains(0) and r.contains(1e-9) and r.contains(1) and not r.contains(1.0001)
    assert Range.parse("[0, inf)").contains(0) and Range.parse("[0, inf)").contains(1e300)


_SECTION = '[[section]]\nname = "beacons"\nread_by = ["bridge", "sim"]\n'
_KEY = '[[section.key]]\nname = "period_s"\ntype = "real"\nunit = "s"\ndoc = "T"\nsim = "required"\n'


@pytest.mark.parametrize("extra, why", [
    ('range = "(0, 10]"\ndefault = 11.0\n', "outside"),
    ('default = 1.0\n', "needs a range"),
    ('range = "(0, 10]"\ndefault = "x"\n', "not a real"),
    ('range = "(0, inf)"\n', "closed above"),
    ('range = "(0, 10]"\ngeometry = "maybe"\n', "geometry"),
    ('range = "(0, 10]"\ngeometry = "library"\n', "without a lib field"),
    ('range = "(0, 10]"\nunits = "s"\n', "unknown schema fields"),
])
def test_bad_schema_is_refused(extra, why):
    with pytest.raises(ValueError, match=why):
        parse_schema(_SECTION + _KEY + extra)


_STRING = ('[[section.key]]\nname = "mode"\ntype = "string"\nunit = ""\ndoc = "m"\n'
           'sim = "ignored"\ndefault = "filter"\n')


@pytest.mark.parametrize("extra, why", [
    ('bridge = "ring.mode"\n', "size is given exactly for a string key of a group"),
    ('size = 16\n', "size is given exactly for a string key of a group"),
    ('bridge = "ring.mode"\nsize = 6\n', "above the default's length"),
    ('bridge = "ring.mode"\nsize = 16.5\n', "must be an integer"),
])
def test_bad_string_size_is_refused(extra, why):
    """A group's string key gives its buffer (the generated struct's member), and only it."""
    with pytest.raises(ValueError, match=why):
        parse_schema(_SECTION + _STRING + extra)


def test_group_string_key_has_its_buffer():
    """The sonar ring's method (a string in a group): its struct member with its buffer."""
    header = c_header(SCHEMA)
    assert "X(sonar_ring)" in header and "X(K_STR, method[16])" in header
    extra = ('\n[[section]]\nname = "probe"\nread_by = ["bridge"]\ndoc = "p"\n'
             '[[section.key]]\nname = "mode"\ntype = "string"\nunit = ""\ndoc = "m"\n'
             'default = "fast"\nbridge = "probe.mode"\nsize = 12\n')
    text = resources.files("beaconloc_sim").joinpath(SCHEMA_RESOURCE).read_text(encoding="utf-8")
    assert "X(K_STR, mode[12])" in c_header(parse_schema(text + extra))


def test_key_declared_twice_is_refused():
    key = _KEY + 'range = "(0, 10]"\n'
    with pytest.raises(ValueError, match="declared twice"):
        parse_schema(_SECTION + key + key)


def test_c_header_rows_are_the_schemas():
    """Every key the bridge reads has one X row, with the schema's range and default."""
    header = c_header(SCHEMA)
    for s in SCHEMA.sections:
        for k in s.keys:
            rows = re.findall(rf"X\({s.name}, {k.name}, [^\n]*\)", header)
            if "bridge" not in s.read_by:
                assert not rows, (s.name, k.name)
                continue
            assert len(rows) >= 1, (s.name, k.name)
            row = rows[0]
            if k.numeric:
                lo, hi, lo_open = (p.strip() for p in row.split(",")[5:8])
                assert float(lo) == k.range.lo and float(hi) == k.range.hi
                assert lo_open == ("true" if k.range.lo_open else "false")
            if k.lib:
                assert re.search(rf"X\({s.name}, {k.name}, K_[A-Z]+, [a-z0-9_.]+, {k.lib}, ",
                                 header) or s.indexed_by, (s.name, k.name)


def _set_key(text: str, section: str, key: str, value) -> str:
    """text with [section] key = value (replaced, or added under the header)."""
    lines, current, header = text.splitlines(), None, None
    for i, line in enumerate(lines):
        if line.startswith("["):
            current = line.strip().strip("[]")
            if current == section:
                header = i
        elif current == section and re.match(rf"{re.escape(key)}\s*=", line):
            lines[i] = f"{key} = {value}"
            return "\n".join(lines) + "\n"
    if header is None:   # an optional section the file does not have
        lines += ["", f"[{section}]"]
        header = len(lines) - 1
    lines.insert(header + 1, f"{key} = {value}")
    return "\n".join(lines) + "\n"


BEARING_TEXT = """
[bearing_beacons]
count = 3

[bearing_beacon1]
x_m = 3.0
y_m = 2.1

[bearing_beacon2]
x_m = 0.0
y_m = 1.05

[bearing_beacon3]
x_m = 3.0
y_m = 0.0

[bearing_sensor]
sigma_deg = 1.0

[range_beacons]
count = 3

[range_beacon1]
x_m = 0.0
y_m = 0.0
z_m = 2.0

[range_beacon2]
x_m = 4.0
y_m = 0.0
z_m = 2.0

[range_beacon3]
x_m = 0.0
y_m = 4.0
z_m = 2.0

[range_sensor]
sigma_m = 0.008
"""

SONAR_TEXT = """
[sonar_ring]
count = 2

[sonar1]
x_m = 0.2
y_m = 0.0
angle_deg = 0

[sonar2]
x_m = 0.1
y_m = 0.1
angle_deg = 45

[map]
walls = 2

[wall1]
x1_m = 0.0
y1_m = 0.0
x2_m = 6.0
y2_m = 0.0

[wall2]
x1_m = 6.0
y1_m = 0.0
x2_m = 6.0
y2_m = 4.0
"""


def _file_value(section: str, key: str, text: str) -> float:
    for sec, k, v in _ini_text_keys(text):
        if (sec, k) == (section, key):
            return float(v)
    raise KeyError((section, key))


def _nudged(k) -> str:
    v = k.default
    if k.type == "int":
        if v is not None and k.sim_range is not None and k.sim_range.hi == 1:
            return str(1 - v)   # a switch: the other position
        return str(v - 1 if v is not None and v > 1 else 4097)
    if v is None or v == 0:
        return "0.01"
    return repr(float(v) * 1.01)


COUNT_KEYS = {(s.indexed_by, s.count_key) for s in SCHEMA.indexed()}
SIM_READ = [(s.name, k) for s in SCHEMA.sections if "sim" in s.read_by for k in s.keys
            if k.sim in ("required", "optional") and k.numeric and (s.name, k.name) not in COUNT_KEYS]


@pytest.mark.parametrize("section, key", SIM_READ, ids=[f"{s}.{k.name}" for s, k in SIM_READ])
def test_simulator_reads_every_schema_key(tmp_path, section, key):
    """A key the schema gives the simulator changes the simulated site (no key dropped)."""
    text = SITE_TEXT + BEARING_TEXT + SONAR_TEXT   # kleeman-lab with bearings and sonars too
    sec = f"{SCHEMA.section(section).prefix}2" if SCHEMA.section(section).indexed_by else section
    base = tmp_path / "base.ini"
    base.write_text(text)
    before = load_site(base)
    changed = tmp_path / "changed.ini"
    if key.default is None:   # required, no default: nudge the file's own value
        value = repr(_file_value(sec, key.name, text) * 1.01 + 0.01)
    else:
        value = _nudged(key)
    changed.write_text(_set_key(text, sec, key.name, value))
    after = load_site(changed)
    differ = [name for name, value in before.attributes().items() if name != "path"
              and not _equal(value, getattr(after, name))]
    assert differ, f"[{sec}] {key.name} = {value} changed nothing the simulator reads"


def _equal(a, b) -> bool:
    return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) else a == b


def test_simulator_applies_the_sim_range(tmp_path):
    """Out of the simulator's range: refused with the key named; inside it: accepted."""
    for section in SCHEMA.sections:
        if "sim" not in section.read_by or section.indexed_by:
            continue
        for k in section.keys:
            if k.sim not in ("required", "optional") or not k.numeric or k.sim_range is None:
                continue
            r = k.sim_range
            if math.isfinite(r.hi) and k.name != "count":
                big = int(r.hi * 2 + 1) if k.type == "int" else r.hi * 2 + 1
                text = _set_key(SITE_TEXT, section.name, k.name, repr(big))
                path = tmp_path / f"{section.name}_{k.name}.ini"
                path.write_text(text)
                with pytest.raises(ConfigError, match=rf"\[{section.name}\] {k.name}: must be <="):
                    load_site(path)


def test_unsupported_key_only_at_its_default(tmp_path):
    """[receivers] angle_step_deg: the bridge's; the simulated ring is evenly spaced (0)."""
    (tmp_path / "even.ini").write_text(_set_key(SITE_TEXT, "receivers", "angle_step_deg", "0"))
    assert load_site(tmp_path / "even.ini").rx_count == 8
    (tmp_path / "odd.ini").write_text(_set_key(SITE_TEXT, "receivers", "angle_step_deg", "40"))
    with pytest.raises(ConfigError, match=r"\[receivers\] angle_step_deg: not simulated"):
        load_site(tmp_path / "odd.ini")
