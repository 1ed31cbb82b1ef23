"""Helpers for the hw_sim tests: scenario files written into tmp_path."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from beaconloc_sim.resources import builtin_site_path

SITE_TEXT = builtin_site_path().read_text()


def site_with(**overrides) -> str:
    """The kleeman-lab site text with 'section.key' = value replaced (section__key in kwargs)."""
    text = SITE_TEXT
    for name, value in overrides.items():
        section, key = name.split("__")
        pattern = re.compile(rf"(\[{re.escape(section)}\][^\[]*?^{re.escape(key)}\s*=)[^\n]*",
                             re.MULTILINE | re.DOTALL)
        text, n = pattern.subn(rf"\g<1> {value}", text)
        assert n == 1, f"no [{section}] {key} in the site text"
    return text


@pytest.fixture
def make_scenario(tmp_path):
    """Write a site + scenario pair; returns the scenario path."""
    counter = {"n": 0}

    def make(body: str, site_text: str | None = None, name: str | None = None) -> Path:
        counter["n"] += 1
        n = counter["n"]
        site = tmp_path / f"site{n}.ini"
        site.write_text(site_text if site_text is not None else SITE_TEXT)
        scn = tmp_path / f"{name or f'test{n}'}.scenario.ini"
        scn.write_text(f"[scenario]\nsite = {site.name}\n" + body)
        return scn
    return make
