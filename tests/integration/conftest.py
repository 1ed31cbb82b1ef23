"""Fixtures of the integration suite.

Every case gets its own vcan interface (created here, deleted after), its
own folder (pytest's tmp_path; the runner puts --basetemp in the results
folder so the logs come back from the VM) and a Rig that starts the real
bridge binary and the real simulator on that interface.

No case skips for lack of a bus: without vcan the suite fails, loudly
(tests/vm/run-in-vm.sh gives it one).
"""
from __future__ import annotations

import itertools
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import harness  # noqa: E402

_iface_numbers = itertools.count(1)


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True)


@pytest.fixture
def can_iface():
    """A fresh, up vcan interface of this test alone."""
    name = f"vcan{next(_iface_numbers)}"
    _ip("link", "del", "dev", name)
    r = _ip("link", "add", "dev", name, "type", "vcan")
    assert r.returncode == 0, (
        f"cannot create {name} ({r.stderr.strip()}): this kernel has no vcan or we are not "
        "root: run the suite through tests/vm/run-in-vm.sh (make test-integration)")
    r = _ip("link", "set", "up", name)
    assert r.returncode == 0, f"cannot bring up {name}: {r.stderr.strip()}"
    yield name
    _ip("link", "del", "dev", name)


@pytest.fixture
def rig(can_iface, tmp_path):
    r = harness.Rig(workdir=tmp_path, iface=can_iface)
    yield r
    r.close()
    # Shown by pytest (and in the junit report) when the case failed.
    print(r.logs())


class _ModuleRig:
    """A rig for a module-scoped run (one live run, several checks)."""

    def __init__(self, tmp_path_factory, name: str):
        self.iface = f"vcan{next(_iface_numbers)}"
        self.workdir = tmp_path_factory.mktemp(name)

    def __enter__(self) -> harness.Rig:
        _ip("link", "del", "dev", self.iface)
        r = _ip("link", "add", "dev", self.iface, "type", "vcan")
        assert r.returncode == 0, (
            f"cannot create {self.iface} ({r.stderr.strip()}): no vcan here; run the suite "
            "through tests/vm/run-in-vm.sh (make test-integration)")
        assert _ip("link", "set", "up", self.iface).returncode == 0
        self.rig = harness.Rig(workdir=self.workdir, iface=self.iface)
        return self.rig

    def __exit__(self, *exc) -> None:
        self.rig.close()
        _ip("link", "del", "dev", self.iface)


@pytest.fixture(scope="module")
def module_rig(tmp_path_factory, request):
    with _ModuleRig(tmp_path_factory, request.module.__name__.rsplit(".", 1)[-1]) as r:
        yield r
