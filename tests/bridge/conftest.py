"""Fixtures for the bridge's pytest suite: the real daemon binary, a
simulator log (beaconloc-sim), free UDP ports. Helpers: bridge_helpers.py."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bridge_helpers import BRIDGE, free_udp_port, run_sim  # noqa: E402


@pytest.fixture(scope="session")
def bridge_bin():
    if not BRIDGE.exists():
        pytest.fail(f"{BRIDGE} not built (make test-bridge-py builds it; BL_BUILD selects the build folder)")
    return BRIDGE


@pytest.fixture(scope="session")
def kleeman_log(tmp_path_factory):
    """A 60 s kleeman-lab run: (log path, truth path)."""
    return run_sim(tmp_path_factory.mktemp("sim"), "kleeman-lab", 60)


@pytest.fixture
def udp_port():
    return free_udp_port()
