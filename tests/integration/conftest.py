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
import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import harness  # noqa: E402


def _worker_index() -> int:
    """0 without pytest-xdist, else N of its worker gwN: live cases run side by
    side, one per worker, and each needs interface names of its own."""
    w = os.environ.get("PYTEST_XDIST_WORKER", "")
    return int(w[2:]) + 1 if w.startswith("gw") and w[2:].isdigit() else 0


# Files whose checks share one module-scoped live run (module_rig): each goes
# whole to one worker. Every other case is a live run of its own.
SHARED_RUN_FILES = ("test_nominal.py", "test_team.py")


def live_run_of(nodeid: str) -> str:
    """The live run a test belongs to: its file where the file shares one
    run, else the test itself."""
    module = nodeid.split("::", 1)[0]
    return module if module.endswith(SHARED_RUN_FILES) else nodeid


def pytest_xdist_make_scheduler(config, log):
    """pytest-xdist's scheduling with one unit per live run (xdist's own
    loadgroup marks are lost on pytest 9, which no longer lets a plugin
    rename a test's nodeid)."""
    from xdist.scheduler import LoadScopeScheduling

    class LiveRunScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return live_run_of(nodeid)

    return LiveRunScheduling(config, log)


# The weight of a live run for sharding: its live_s mark (the simulated
# seconds it runs in real time), else LIVE_S_UNMARKED; plus RUN_OVERHEAD_S
# (start-up of simulator and bridge, the checks) each.
LIVE_S_UNMARKED = 10.0
RUN_OVERHEAD_S = 5.0


def shard_runs(runs: list[str], seconds: dict[str, float], n: int) -> dict[str, int]:
    """Guest of each live run: longest first, each to the guest with the least
    work so far (Graham's LPT rule: the longest guest within 4/3 of the best
    split), ties to the lower guest and the earlier run: deterministic, the
    same in every guest."""
    load, owner = [0.0] * n, {}
    for k in sorted(range(len(runs)), key=lambda k: (-seconds[runs[k]], k)):
        g = min(range(n), key=lambda g: (load[g], g))
        owner[runs[k]] = g
        load[g] += seconds[runs[k]] + RUN_OVERHEAD_S
    return owner


def pytest_collection_modifyitems(config, items):
    """BL_IT_SHARD=I/N (set by tests/vm/run_in_vm.py --guests N): keep the
    live runs shard_runs gives guest I, in collection order, so N guests side
    by side share the suite in about equal time; every test of one live run
    stays together."""
    shard = os.environ.get("BL_IT_SHARD", "")
    if not shard:
        return
    i, n = (int(v) for v in shard.split("/"))
    assert 0 <= i < n, f"BL_IT_SHARD={shard}: want I/N with 0 <= I < N"
    runs = list(dict.fromkeys(live_run_of(it.nodeid) for it in items))
    seconds = dict.fromkeys(runs, 0.0)
    for it in items:
        mark = it.get_closest_marker("live_s")
        run = live_run_of(it.nodeid)
        seconds[run] = max(seconds[run], float(mark.args[0]) if mark else LIVE_S_UNMARKED)
    owner = shard_runs(runs, seconds, n)
    mine = {r for r in runs if owner[r] == i}
    keep = [it for it in items if live_run_of(it.nodeid) in mine]
    drop = [it for it in items if live_run_of(it.nodeid) not in mine]
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


# vcan1, vcan2, ... alone; vcan101, vcan102, ... on worker gw0, vcan201 on gw1.
_iface_numbers = itertools.count(100 * _worker_index() + 1)


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
