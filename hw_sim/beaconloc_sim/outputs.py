"""CSV and JSON outputs of a run (column contracts in docs/simulator.md)."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from .physics.pulses import KIND_DIRECT, KIND_FLOOR_CEILING, KIND_LATE, KIND_WALL
from .dbc import message_names
from .simulate import ODOMETRY_COLUMNS, TRUTH_COLUMNS, SimResult

_INT_COLUMNS = {"t_us", "robot", "beacon"}   # robot, beacon: team truth (team_sim)


def write_csv(path: str | Path, columns: tuple[str, ...], data: dict[str, np.ndarray]) -> int:
    """Write columns in order; t_us as integers, the rest with full float precision."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        fh.write(",".join(columns) + "\n")
        return append_csv_rows(fh, columns, data)


def append_csv_rows(fh, columns: tuple[str, ...], data: dict[str, np.ndarray]) -> int:
    """Rows of write_csv (no header) onto an open file: a run written window by window."""
    n = len(data[columns[0]])
    cols = [np.asarray(data[c]) for c in columns]
    for i in range(n):
        fh.write(",".join(str(int(c[i])) if name in _INT_COLUMNS else repr(float(c[i]))
                          for name, c in zip(columns, cols)) + "\n")
    return n


def write_truth(path, result: SimResult) -> int:
    return write_csv(path, TRUTH_COLUMNS, result.truth)


def write_odometry(path, result: SimResult) -> int:
    return write_csv(path, ODOMETRY_COLUMNS, result.odometry)


def read_csv(path: str | Path, required: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Numeric CSV with a header; errors name the file, line and column."""
    path = Path(path)
    try:
        fh = open(path, newline="", encoding="utf-8")
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    with fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None:
            raise ValueError(f"{path}: empty file (expected a header: {','.join(required)})")
        header = [h.strip() for h in header]
        missing = [c for c in required if c not in header]
        if missing:
            raise ValueError(f"{path}:1: missing column(s) {', '.join(missing)}")
        rows = []
        for lineno, row in enumerate(reader, start=2):
            if not row:
                continue
            if len(row) != len(header):
                raise ValueError(f"{path}:{lineno}: {len(row)} fields, header has {len(header)}")
            try:
                rows.append([float(v) for v in row])
            except ValueError:
                bad = next((h, v) for h, v in zip(header, row) if not _is_float(v))
                raise ValueError(f"{path}:{lineno}: column {bad[0]}: not a number: {bad[1]!r}") from None
    arr = np.array(rows, dtype=float).reshape(-1, len(header))
    return {h: arr[:, i] for i, h in enumerate(header)}


def _is_float(v: str) -> bool:
    try:
        float(v)
        return True
    except ValueError:
        return False


def run_stats(result: SimResult, *, wall_time_s: float, lateness_s: np.ndarray | None = None,
              sent: int | None = None) -> dict:
    fr = result.frames
    ids = fr.arb_id
    det = result.detections
    names = message_names()
    n_total = len(fr) if sent is None else sent
    by_id = {f"0x{fid:03X}": int(np.sum(ids[:n_total] == fid)) for fid in names}
    stats = {
        "scenario": result.scenario.name,
        "seed": result.scenario.seed,
        "duration_s": result.scenario.duration_s,
        "frames": {**by_id, "total": int(n_total)},
        "frames_by_name": {names[fid]: by_id[f"0x{fid:03X}"] for fid in names},
        "firings": int(len(result.firings.t_s)),
        "firings_dead": int(np.sum(~result.firings.alive)),
        "detections": {
            "direct": int(np.sum(det.kind == KIND_DIRECT)),
            "wall_echo": int(np.sum(det.kind == KIND_WALL)),
            "floor_ceiling_echo": int(np.sum(det.kind == KIND_FLOOR_CEILING)),
            "late_arrival": int(np.sum(det.kind == KIND_LATE)),
            "double_pulse": int(np.sum(det.double)),
            "saturated": int(np.sum(det.saturated)),
        },
        "sim_time_s": float(result.scenario.duration_s),
        "wall_time_s": wall_time_s,
    }
    # each sensor kind's record of the run counts itself (its stats(), nodes/<kind>.py)
    stats.update({name: record.stats() for name, record in result.measured().items()})
    if lateness_s is not None:
        late_us = np.asarray(lateness_s) * 1e6
        stats["live"] = {
            "frames_sent": int(len(late_us)),
            "lateness_us": {
                "p50": float(np.percentile(late_us, 50)) if len(late_us) else None,
                "p99": float(np.percentile(late_us, 99)) if len(late_us) else None,
                "max": float(np.max(late_us)) if len(late_us) else None,
            },
            "frames_late_over_1ms": int(np.sum(late_us > 1000.0)),
        }
    return stats


def add_stats(total: dict | None, part: dict) -> dict:
    """run_stats of consecutive windows of one run, added up (counts summed; wall_time_s,
    duration_s and sim_time_s of the whole run are set by the caller)."""
    if total is None:
        return json.loads(json.dumps(part))
    for key, value in part.items():
        if isinstance(value, dict):
            add_stats(total.setdefault(key, {}), value)
        elif isinstance(value, int) and not isinstance(value, bool) and key != "seed":
            total[key] = total.get(key, 0) + value
    return total


def write_json(path, obj) -> None:
    Path(path).write_text(json.dumps(obj, indent=2) + "\n", encoding="utf-8")
