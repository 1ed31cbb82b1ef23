"""The package's data, through importlib.resources: the DBC (the single source of truth
for every frame) and the built-in scenarios with their site file.

Layout inside the package: ``data/beaconloc.dbc``, ``data/scenarios/<name>.scenario.ini``
and the site file they name (``data/scenarios/kleeman-lab.ini``). They are package data
(hw_sim/pyproject.toml), so an installed copy of the package carries them; pip installs a
package as files, so each is handed out as a file-system path (the scenario loader reads
the site file it names relative to it, and the bridge's build reads the DBC by path).
"""
from __future__ import annotations

import atexit
import contextlib
from importlib import resources
from pathlib import Path

SCENARIO_SUFFIX = ".scenario.ini"
_files = contextlib.ExitStack()
atexit.register(_files.close)


def _data():
    return resources.files(__package__).joinpath("data")


def _path(resource) -> Path:
    """A packaged file as a file-system path (kept until the interpreter exits)."""
    return _files.enter_context(resources.as_file(resource))


def dbc_path() -> Path:
    return _path(_data().joinpath("beaconloc.dbc"))


def builtin_scenario_names() -> list[str]:
    return sorted(r.name[: -len(SCENARIO_SUFFIX)] for r in _data().joinpath("scenarios").iterdir()
                  if r.name.endswith(SCENARIO_SUFFIX))


def builtin_scenario_path(name: str) -> Path | None:
    """The packaged scenario file of a built-in name, None when there is none."""
    resource = _data().joinpath("scenarios").joinpath(name + SCENARIO_SUFFIX)
    return _path(resource) if resource.is_file() else None


def builtin_site_path(name: str = "kleeman-lab") -> Path:
    """A packaged site file (the one the built-in scenarios name)."""
    return _path(_data().joinpath("scenarios").joinpath(name + ".ini"))
