"""A non-editable install carries its data: `pip install ./hw_sim` into a fresh venv,
then the console command runs a packaged scenario from outside the repository and
writes the same log as the development copy; beaconloc-view serves its packaged page."""
from __future__ import annotations

import json
import shutil
import site
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from beaconloc_sim.cli import main as cli_main

HW_SIM = Path(__file__).resolve().parents[2] / "hw_sim"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A fresh venv with beaconloc-sim installed from a copy of hw_sim/ (not editable).
    No download: the dependencies and the build backend (setuptools) are this
    interpreter's, made visible by a .pth line; pip runs with --no-index."""
    tmp = tmp_path_factory.mktemp("install")
    src = tmp / "hw_sim"
    shutil.copytree(HW_SIM, src, ignore=shutil.ignore_patterns("*.egg-info", "build",
                                                                "__pycache__"))
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    purelib = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                             check=True, capture_output=True, text=True).stdout.strip()
    Path(purelib, "deps-from-test.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check",
                    "--no-index", "--no-deps", "--no-build-isolation", str(src)],
                   check=True, cwd=tmp)
    shutil.rmtree(src)            # the installed copy must not need its source
    return venv, Path(purelib)


def test_installed_package_runs_a_packaged_scenario(installed, tmp_path):
    venv, purelib = installed
    out = tmp_path / "out"
    out.mkdir()
    where = subprocess.run([str(venv / "bin" / "python"), "-c",
                            "import beaconloc_sim.resources as r; print(r.dbc_path()); "
                            "print(r.builtin_scenario_path('kleeman-lab'))"],
                           check=True, capture_output=True, text=True, cwd=out).stdout.split()
    assert [Path(p).parent for p in where] == [purelib / "beaconloc_sim" / "data",
                                               purelib / "beaconloc_sim" / "data" / "scenarios"]
    listed = subprocess.run([str(venv / "bin" / "beaconloc-sim"), "list"], check=True,
                            capture_output=True, text=True, cwd=out).stdout
    assert "kleeman-lab" in listed and "BROKEN" not in listed
    subprocess.run([str(venv / "bin" / "beaconloc-sim"), "run", "echo-storm", "--duration", "3",
                    "--log", "installed.log", "--truth", "installed.csv"], check=True, cwd=out)
    assert cli_main(["run", "echo-storm", "--duration", "3", "--log", str(tmp_path / "dev.log"),
                     "--truth", str(tmp_path / "dev.csv")]) == 0
    installed_log = (out / "installed.log").read_bytes()
    assert installed_log.count(b"\n") > 100
    assert installed_log == (tmp_path / "dev.log").read_bytes()
    assert (out / "installed.csv").read_bytes() == (tmp_path / "dev.csv").read_bytes()


def test_installed_view_serves_its_packaged_page(installed, tmp_path):
    """beaconloc-view from the installed copy: its page is package data (page.html)."""
    venv, purelib = installed
    url_file = tmp_path / "url"
    proc = subprocess.Popen([str(venv / "bin" / "beaconloc-view"), "--site", "kleeman-lab",
                             "--mavlink", "udpin:127.0.0.1:0", "--port", "0", "--url-file",
                             str(url_file)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        for _ in range(300):
            if url_file.exists() or proc.poll() is not None:
                break
            time.sleep(0.1)
        assert url_file.exists(), proc.stdout.read().decode() if proc.poll() is not None else ""
        url = url_file.read_text().strip()
        page = urllib.request.urlopen(url, timeout=10).read()
        assert page == (purelib / "beaconloc_sim" / "view" / "page.html").read_bytes()
        site = json.loads(urllib.request.urlopen(url + "site.json", timeout=10).read())
        assert site["name"] == "kleeman-lab" and len(site["beacons"]) == 6
    finally:
        proc.terminate()
        proc.wait(timeout=10)
