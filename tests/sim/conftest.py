"""Helpers for the hw_sim tests: scenario files written into tmp_path."""
from __future__ import annotations

import os
import re
import sys
from pathlib import Path


def _pin_blas_kernel() -> None:
    """The *_unchanged tests compare the sha256 of the simulator's truth CSV
    (full precision) with one recorded earlier. Its bound's matrix products
    go through OpenBLAS, which picks its kernels by CPU: on a machine with
    AVX-512 its SkylakeX kernels sum in another order than the Haswell
    (AVX2) ones the hashes were recorded with, and the truth differed in the
    last bits (a fresh-clone CI run of 2026-12-03, six tests). Pin the Haswell
    kernels wherever the CPU can run them (AVX2 and FMA), before numpy loads
    OpenBLAS: the simulator's outputs are then the same on every such
    machine. The subprocesses the tests start inherit it."""
    if "numpy" in sys.modules or "OPENBLAS_CORETYPE" in os.environ:
        return
    try:
        flags = next(line for line in open("/proc/cpuinfo") if line.startswith("flags")).split()
    except (OSError, StopIteration):
        return
    if "avx2" in flags and "fma" in flags:
        os.environ["OPENBLAS_CORETYPE"] = "Haswell"


_pin_blas_kernel()

import pytest  # noqa: E402

from beaconloc_sim.resources import builtin_site_path  # noqa: E402

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
