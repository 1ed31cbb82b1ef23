"""Plot a run: truth vs estimate vs odometry alone (xy), position error with the
estimator's 3-sigma envelope and the Cramer-Rao bound, speed of sound."""
from __future__ import annotations

import numpy as np

from .outputs import read_csv

TRUTH_NEEDED = ("t_us", "x_m", "y_m", "sos_mps", "pcrb_pos_m")
EST_NEEDED = ("t_us", "x_m", "y_m", "sos_mps", "var_x_m2", "var_y_m2")
ODO_NEEDED = ("t_us", "x_m", "y_m")


def match_truth(truth: dict, t_us: np.ndarray, column: str) -> np.ndarray:
    """Truth column linearly interpolated at the estimate times (both on the receiver-array clock)."""
    return np.interp(t_us, truth["t_us"], truth[column])


def plot(truth_path, estimates_path, odometry_path, out_path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    truth = read_csv(truth_path, TRUTH_NEEDED)
    est = read_csv(estimates_path, EST_NEEDED)
    odo = read_csv(odometry_path, ODO_NEEDED) if odometry_path else None
    if len(truth["t_us"]) < 2:
        raise ValueError(f"{truth_path}: fewer than 2 rows")
    inside = (est["t_us"] >= truth["t_us"][0]) & (est["t_us"] <= truth["t_us"][-1])
    est = {k: v[inside] for k, v in est.items()}
    if not len(est["t_us"]):
        raise ValueError(f"{estimates_path}: no estimate inside the truth's time span "
                         f"(t_us {int(truth['t_us'][0])}..{int(truth['t_us'][-1])})")
    t0 = truth["t_us"][0]
    t_est = (est["t_us"] - t0) * 1e-6
    t_tru = (truth["t_us"] - t0) * 1e-6
    err = np.hypot(est["x_m"] - match_truth(truth, est["t_us"], "x_m"),
                   est["y_m"] - match_truth(truth, est["t_us"], "y_m"))
    sigma = np.sqrt(np.maximum(est["var_x_m2"] + est["var_y_m2"], 0.0))

    fig, ax = plt.subplots(1, 3, figsize=(17, 5.5))
    ax[0].plot(truth["x_m"], truth["y_m"], "k-", lw=1.5, label="truth", zorder=3)
    ax[0].plot(est["x_m"], est["y_m"], "C0-", lw=0.9, label="estimate")
    if odo is not None:
        ax[0].plot(odo["x_m"], odo["y_m"], "C3--", lw=0.9, label="odometry alone")
    ax[0].set(xlabel="x (m)", ylabel="y (m)", title="path", aspect="equal")
    ax[0].legend(loc="best")
    ax[0].grid(alpha=0.3)

    ax[1].semilogy(t_est, np.maximum(err, 1e-5) * 1e3, "C0-", lw=0.8, label="position error")
    ax[1].semilogy(t_est, np.maximum(3 * sigma, 1e-5) * 1e3, "C1-", lw=0.8,
                   label="estimator 3$\\sigma$")
    ax[1].semilogy(t_tru, truth["pcrb_pos_m"] * 1e3, "k--", lw=1.0, label="Cramer-Rao bound (1$\\sigma$)")
    ax[1].set(xlabel="time (s)", ylabel="mm", title="position error")
    ax[1].legend(loc="best")
    ax[1].grid(alpha=0.3, which="both")

    ax[2].plot(t_tru, truth["sos_mps"], "k-", lw=1.5, label="truth")
    ax[2].plot(t_est, est["sos_mps"], "C0-", lw=0.8, label="estimate")
    ax[2].set(xlabel="time (s)", ylabel="m/s", title="speed of sound")
    ax[2].legend(loc="best")
    ax[2].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_path, dpi=110)
    plt.close(fig)


# contour levels of the accuracy map, cm (the 5 cm one drawn heavy: Vander Fig. 5's figure)
MAP_LEVELS_CM = (0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100)


def draw_walls(ax, site, obstacles_m=None, color: str = "black") -> None:
    """A site's map walls ([wallN], thick, labelled "map wall") and, when given, a scenario's
    obstacles (segments not in the map, red, "not in the map") on a matplotlib axis: the
    floor plan of the sonar figures (beaconloc-sim map, the sonar benchmark's paths)."""
    for i, (x1, y1, x2, y2) in enumerate(site.walls_m):
        ax.plot([x1, x2], [y1, y2], color=color, lw=3, solid_capstyle="butt",
                label="map wall" if i == 0 else None, zorder=4)
    for i, (x1, y1, x2, y2) in enumerate(() if obstacles_m is None else obstacles_m):
        ax.plot([x1, x2], [y1, y2], color="tab:red", lw=2, solid_capstyle="butt",
                label="not in the map" if i == 0 else None, zorder=4)


def plot_map(site, maps, out_path, split_x_m: float | None = None) -> None:
    """The planner's accuracy maps side by side: filled drms contours (cm, levels
    MAP_LEVELS_CM), the 5 cm contour heavy, degenerate cells hatched grey, beacons drawn;
    a dashed line at x = split_x_m (m) when given (the halves of Vander Fig. 5)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm
    from matplotlib.patches import Patch

    aspect = site.room_y_m / site.room_x_m
    width = 5.6
    fig, axes = plt.subplots(1, len(maps), figsize=(width * len(maps), width * aspect + 1.3),
                             squeeze=False)
    cmap = plt.get_cmap("viridis", len(MAP_LEVELS_CM) + 1)
    norm = BoundaryNorm(MAP_LEVELS_CM, cmap.N, extend="both")
    for ax, m in zip(axes[0], maps):
        # cell centres padded out to the walls with the edge cells' values
        xs = np.concatenate([[0.0], m.x_m, [site.room_x_m]])
        ys = np.concatenate([[0.0], m.y_m, [site.room_y_m]])
        drms_cm = np.pad(m.drms_m * 100, 1, mode="edge")
        degenerate = np.pad(m.degenerate, 1, mode="edge")
        ax.set_facecolor("0.8")      # degenerate cells: NaN, not filled
        cs = ax.contourf(xs, ys, drms_cm, levels=MAP_LEVELS_CM, cmap=cmap, norm=norm,
                         extend="both")
        if degenerate.any():
            ax.contourf(xs, ys, degenerate.astype(float), levels=[0.5, 1.5],
                        colors="none", hatches=["////"])
        if np.nanmin(drms_cm, initial=np.inf) < 5 < np.nanmax(drms_cm, initial=-np.inf):
            c5 = ax.contour(xs, ys, drms_cm, levels=[5], colors="red", linewidths=2.2)
            ax.clabel(c5, fmt="5 cm", fontsize=8)
        fig.colorbar(cs, ax=ax, label="position drms (cm)", ticks=MAP_LEVELS_CM, shrink=0.8)
        beacons = []
        if m.kind in ("tdoa", "both") and site.beacon_count:
            beacons.append((site.beacons_m, "s", "ultrasonic beacon", "U"))
        if m.kind in ("bearing", "both") and site.bearing_beacon_count:
            beacons.append((site.bearing_beacons_m, "^", "bearing beacon", "B"))
        if m.kind in ("range", "both") and site.range_beacon_count:
            beacons.append((site.range_beacons_m, "o", "range beacon", "R"))
        for pts, marker, label, prefix in beacons:
            ax.plot(pts[:, 0], pts[:, 1], marker, color="white", mec="black", ms=9,
                    clip_on=False, zorder=5, label=label)
            for i, p in enumerate(pts):
                ax.annotate(f"{prefix}{i + 1}", (p[0], p[1]), textcoords="offset points",
                            xytext=(6, 4), fontsize=8, annotation_clip=False)
        if m.kind == "sonar":          # the map the sonars are matched against
            draw_walls(ax, site, color="white")
        if split_x_m is not None:
            ax.axvline(split_x_m, color="white", ls="--", lw=1)
        handles = ax.get_legend_handles_labels()[0]
        handles.append(Patch(facecolor="0.8", hatch="////", label="degenerate"))
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3,
                  fontsize=8, frameon=False)
        s = m.stats()
        title = f"{site.name}: {m.kind}, " + (f"median {s['drms_median_mm']:.0f} mm"
                                              if s["degenerate_pct"] < 100 else "all degenerate")
        if len(m.headings_rad) > 1:
            title += f", worst of {len(m.headings_rad)} headings"
        ax.set(xlim=(0, site.room_x_m), ylim=(0, site.room_y_m), aspect="equal",
               xlabel="x (m)", ylabel="y (m)")
        ax.set_title(title, pad=14)
    fig.tight_layout()
    fig.savefig(out_path, dpi=100, bbox_inches="tight")
    plt.close(fig)
