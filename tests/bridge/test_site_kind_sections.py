"""A new kind's site sections reach the bridge from the site schema alone (issue 10).

A throwaway kind, "probe", is added to a copy of the schema: its count section
[probe_beacons] (with its clause of the site-validity rule: 2 beacons start the
filter alone), its per-item section [probe_beaconN] and its sensor section
[probe_sensor] (keys "probe_sensor.<key>"). The header generated from that copy
must give struct bridge_config its members (probe_beacon_count, probe_beacon[],
probe_sensor) and the bridge's config.c and site_to_lib.c must compile against it
unedited: config.h, config.c and site_to_lib.c name no kind's site section.
"""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from beaconloc_sim.site_schema import c_header, parse_schema

REPO = Path(__file__).resolve().parents[2]
SCHEMA_TOML = REPO / "hw_sim/beaconloc_sim/data/site_schema.toml"
BUILD = REPO / os.environ.get("BL_BUILD", "build")

def _toml(table: str, **fields) -> str:
    """One TOML table ([[section]] or [[section.key]]) of the schema."""
    rows = "\n".join(f"{k} = {v!r}".replace("'", '"') for k, v in fields.items())
    return f"\n[[{table}]]\n{rows}\n"


def _key(name: str, type_: str, rng: str, **extra) -> str:
    return _toml("section.key", name=name, type=type_, unit="", range=rng, doc=name, **extra)


# The throwaway kind: [probe_beacons] count, [probe_beaconN] x_m (required),
# [probe_sensor] gain, channels, mode (a string of 12 bytes; with defaults).
PROBE = (_toml("section", name="probe_beacons", read_by=["bridge"], doc="test only",
               starts_alone=["count >= 2"])
         + _key("count", "int", "[0, 5]", default=0, bridge="probe_beacon_count")
         + _toml("section", name="probe_beaconN", read_by=["bridge"],
                 indexed_by="probe_beacons", doc="test only")
         + _key("x_m", "real", "[-100, 100]")
         + _toml("section", name="probe_sensor", read_by=["bridge"], doc="test only")
         + _key("gain", "real", "(0, 10]", default=2.5, bridge="probe_sensor.gain")
         + _key("channels", "int", "[1, 4]", default=1, bridge="probe_sensor.channels")
         + _toml("section.key", name="mode", type="string", unit="", doc="mode",
                 default="fast", bridge="probe_sensor.mode", size=12))

PROBE_C = r'''
#include <stddef.h>
#include <string.h>
#include "config.h"

_Static_assert(sizeof(((struct bridge_config *)0)->probe_beacon) ==
                   5 * sizeof(struct config_probe_beacon), "[probe_beaconN]: 5 items");
_Static_assert(sizeof(((struct bridge_config *)0)->probe_beacon_count) == sizeof(int),
               "[probe_beacons] count");
_Static_assert(sizeof(((struct bridge_config *)0)->probe_sensor.gain) == sizeof(double),
               "[probe_sensor] gain");
_Static_assert(sizeof(((struct bridge_config *)0)->probe_sensor.channels) == sizeof(int),
               "[probe_sensor] channels");
_Static_assert(sizeof(((struct bridge_config *)0)->probe_sensor.mode) == 12,
               "[probe_sensor] mode: a string of the schema's size");

int main(void)
{
    struct bridge_config c;
    config_defaults(&c);
    /* the schema's defaults, set by config.c's generated table */
    if (!(c.probe_sensor.gain == 2.5 && c.probe_sensor.channels == 1 &&
          c.probe_beacon_count == 0 && strcmp(c.probe_sensor.mode, "fast") == 0))
        return 1;
    /* its clause of the site-validity rule: 2 probe beacons start the filter alone */
    char err[CONFIG_ERR_LEN];
    c.probe_beacon_count = 1;
    if (config_site_starts(&c) || config_check(&c, err, sizeof err) == 0 ||
        !strstr(err, "[team] robots >= 1 (now 0) or [probe_beacons] count >= 2 (now 1)"))
        return 2;
    c.probe_beacon_count = 2;
    return config_site_starts(&c) ? 0 : 3;
}
'''


def _cc() -> str:
    cc = os.environ.get("CC", "cc")
    if not shutil.which(cc):
        pytest.skip(f"no C compiler {cc}")
    return cc


def test_probe_kind_builds_into_bridge_config(tmp_path):
    text = SCHEMA_TOML.read_text(encoding="utf-8") + PROBE
    header = c_header(parse_schema(text))
    assert "X(probe_sensor)" in header and "X(probe_beacons, probe_beacon_count)" in header
    gen = tmp_path / "gen"
    gen.mkdir()
    (gen / "site_keys.h").write_text(header, encoding="utf-8")
    (tmp_path / "probe.c").write_text(PROBE_C, encoding="utf-8")
    cangen = BUILD / "gen" / "can"
    libgen = BUILD / "gen" / "lib"  # the library's generated kinds' list (lib/lib.mk)
    flags = ["-std=c11", "-D_GNU_SOURCE", "-Wall", "-Wextra", "-Werror", f"-I{gen}",
             f"-I{REPO / 'bridge'}", f"-I{REPO / 'lib/include'}", f"-I{libgen}", f"-I{cangen}"]
    cc = _cc()
    objs = []
    for src in (tmp_path / "probe.c", REPO / "bridge/config.c", REPO / "bridge/log.c",
                REPO / "bridge/site_to_lib.c"):
        obj = tmp_path / (src.stem + ".o")
        p = subprocess.run([cc, *flags, "-c", "-o", str(obj), str(src)],
                           capture_output=True, text=True)
        assert p.returncode == 0, f"{src.name} does not build from the schema alone:\n{p.stderr}"
        objs.append(obj)
    # config.c's parser, defaults and checks link and run with the probe kind
    # (site_to_lib.o: the library's mapping; only config_same_geometry and the
    # error path use it)
    lib = BUILD / "lib" / "libbeaconloc.a"
    if not lib.exists():
        pytest.skip(f"{lib} not built")
    exe = tmp_path / "probe"
    p = subprocess.run([cc, "-o", str(exe), *map(str, objs), str(lib), "-linih", "-lm",
                        "-lstdc++"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert subprocess.run([str(exe)]).returncode == 0
