"""Unique poses (the paper's Algorithm 1, eq. 1): section spectra, divergence, where the unique
poses lie, rotation invariance.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..grid import OccupancyGrid
from .grids import _new_figure, plot_grid, robot_colour

__all__ = ["plot_section_spectra", "plot_divergence", "plot_unique_poses", "plot_unique_summary",
           "plot_unique_in_world", "plot_rotation_invariance"]


def plot_section_spectra(unique, poses, *, labels=None):
    """The overall spectrum against the spectra of a few sections (Algorithm 1, lines 1-6).

    One panel per pose in ``poses``: the robot's overall spectrum (mean of all its scans'
    ``|DFT|``, thick black) and the spectra of the ``2 * sub_sec`` scans of the pose's section
    (thin, coloured from the first scan of the section to the last).

    Parameters
    ----------
    unique : UniquePoses
    poses : sequence of int
        Pose indices (each must have a full section).
    labels : sequence of str, optional
        Panel titles' first words (default "pose i").

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib as mpl
    from matplotlib.lines import Line2D

    poses = [int(p) for p in poses]
    s = unique.sub_sec
    n = unique.spectra.shape[0]
    for p in poses:
        if not s <= p < n - s:
            raise InputError(f"pose {p} has no full section; use a pose in [{s}, {n - s})")
    labels = list(labels) if labels is not None else [f"pose {p}" for p in poses]
    fig = _new_figure(6.3 * len(poses), 4.8)
    axes = np.atleast_1d(fig.subplots(1, len(poses), sharey=True))
    u = np.arange(1, unique.spectra.shape[1] + 1)  # bin 0 (DC) is left out by default
    cmap = mpl.colormaps["viridis"]
    for ax, p, lab in zip(axes, poses, labels):
        sec = range(p - s, p + s)
        for j, k in enumerate(sec):
            ax.plot(u, unique.spectra[k], "-", lw=0.8, color=cmap(j / max(1, 2 * s - 1)), alpha=0.8)
        ax.plot(u, unique.overall_spectrum, "-", color="k", lw=2.2)
        ax.set_yscale("log")
        ax.set_xscale("log")
        ax.set_xlabel("frequency u (cycles per turn of the scan)")
        verdict = "unique" if unique.section_score[p] >= unique.delta else "typical"
        div = unique.divergence[list(sec)]
        below = int((div < unique.delta).sum())
        ax.set_title(f"{lab}: {verdict} ({below} of {2 * s} scans within delta of o_spec)",
                     fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(handles=[Line2D([], [], color="k", lw=2.2, label="overall spectrum o_spec (all poses)"),
                           Line2D([], [], color=cmap(0.0), lw=1, label=f"scan {p - s} (first of section)"),
                           Line2D([], [], color=cmap(1.0), lw=1, label=f"scan {p + s - 1} (last of section)")],
                  loc="lower left", fontsize=8, framealpha=0.9)
    axes[0].set_ylabel("|DFT(u)| (m)")
    return fig


def plot_divergence(ax, unique, *, window=None, title: str | None = None):
    """Algorithm 1 along the trajectory: each scan's divergence from the overall spectrum
    (line 6), the section score (the 2nd smallest divergence in the section) against delta, and
    the unique poses it gives (line 15).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    unique : UniquePoses
    window : (start, stop), optional
        Range of pose indices to draw.
    title : str, optional
    """
    n = unique.divergence.size
    a, b = (0, n) if window is None else (max(0, int(window[0])), min(n, int(window[1])))
    idx = np.arange(a, b)
    ax.plot(idx, unique.divergence[a:b], "-", color="0.6", lw=0.6,
            label="divergence of each scan: sum |spec - o_spec|")
    score = unique.section_score[a:b]
    ok = np.isfinite(score)
    ax.plot(idx[ok], score[ok], "-", color="tab:blue", lw=1.0,
            label="section score: 2nd smallest divergence in the section")
    ax.axhline(unique.delta, color="tab:red", ls="--", lw=1.2, label=f"delta = {unique.delta:.0f} m x beams")
    sel = unique.indices[(unique.indices >= a) & (unique.indices < b)]
    ax.plot(sel, unique.section_score[sel], "o", color="tab:red", ms=3,
            label=f"unique poses ({sel.size} here, {unique.count} in all)")
    ax.set_xlim(a, b - 1)
    ax.set_xlabel("pose index along the trajectory")
    ax.set_ylabel("divergence (m x beams)")
    ax.set_title(title if title is not None else
                 f"Algorithm 1: a pose is unique when at most 1 scan of its section is within "
                 f"delta (sub_sec = {unique.sub_sec})")
    ax.legend(loc="upper left", fontsize=8, framealpha=0.9, ncol=2)
    ax.grid(alpha=0.3)


def plot_unique_poses(ax, grid: OccupancyGrid, log, unique, *, colour: str = "tab:red",
                      title: str | None = None):
    """A robot's map with its trajectory and its unique poses (own frame, m)."""
    plot_grid(ax, grid, title="")
    ax.plot(log.poses[:, 0], log.poses[:, 1], "-", color="0.5", lw=0.5, alpha=0.8,
            label="trajectory")
    p = log.poses[unique.indices]
    ax.plot(p[:, 0], p[:, 1], "o", color=colour, ms=3.5, mec="k", mew=0.3,
            label=f"unique poses ({unique.count})")
    ax.set_title(title if title is not None else
                 f"{grid.name or 'map'}: where the unique poses are")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)


def plot_unique_summary(grid: OccupancyGrid, log, unique, *, colour: str = "tab:red"):
    """Divergence along the trajectory (left) and the unique poses on the map (right)."""
    fig = _new_figure(15.0, 5.0)
    ax_d, ax_m = fig.subplots(1, 2, width_ratios=[1.6, 1.0])
    plot_divergence(ax_d, unique)
    plot_unique_poses(ax_m, grid, log, unique, colour=colour)
    return fig


def plot_unique_in_world(world: OccupancyGrid, trajectories, unique_list, names=None):
    """Every robot's unique poses where they truly are in the world (for teaching: the
    merger never sees the world frame). Distinctive places collect the unique poses of
    several robots; that is what pairing (eq. 2) relies on.

    Parameters
    ----------
    world : OccupancyGrid
    trajectories : sequence of (P, 3) arrays
        True world poses of each robot (``RobotRun.trajectory``).
    unique_list : sequence of UniquePoses
    names : sequence of str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = list(names) if names is not None else [f"robot_{k + 1}" for k in range(len(unique_list))]
    fig = _new_figure(10.0, 7.0)
    ax = fig.subplots()
    plot_grid(ax, world, title="", alpha=0.7)
    for k, (traj, u) in enumerate(zip(trajectories, unique_list)):
        p = np.asarray(traj)[u.indices]
        ax.plot(p[:, 0], p[:, 1], "o", color=robot_colour(k), ms=4, mec="k", mew=0.3, alpha=0.85,
                label=f"{names[k]}: {u.count} unique poses")
    ax.set_title("Unique poses of every robot, at their true places in the world")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    return fig


def plot_rotation_invariance(log, index: int, turn_deg: float):
    """Why spectra can be compared between robots: turning the robot shifts its scan
    circularly, which leaves ``|DFT|`` unchanged and moves only the phase.

    Panels: the scan and the scan of the same place with the robot turned by ``turn_deg``
    (rounded to whole beams); both magnitude spectra; the phase difference per frequency, a
    straight line whose slope is the turn.

    Parameters
    ----------
    log : ScanLog
        A 360-degree scan log.
    index : int
        Which scan.
    turn_deg : float
        How far the robot turns (degrees, counter-clockwise).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from ..unique_poses import scan_spectra

    if log.field_of_view < 2 * np.pi - 1e-6:
        raise InputError("rotation invariance holds for 360-degree scans only")
    r = log.clipped_ranges()[index].astype(float)
    B = r.size
    k = int(round(np.radians(turn_deg) / log.angle_increment))
    # turning the robot by +k beams: what was at beam j + k is now at beam j
    turned = np.roll(r, -k)
    deg = np.degrees(log.beam_angles)
    spec = scan_spectra(np.stack([r, turned]), dc=False)
    u = np.arange(1, spec.shape[1] + 1)
    fig = _new_figure(16.0, 4.6)
    a1, a2, a3 = fig.subplots(1, 3)
    a1.plot(deg, r, "-", color="tab:blue", lw=1.0, label="scan")
    a1.plot(deg, turned, "-", color="tab:orange", lw=1.0,
            label=f"same place, robot turned {np.degrees(k * log.angle_increment):.0f} deg")
    a1.set_xlabel("beam angle relative to the heading (deg)")
    a1.set_ylabel("range (m)")
    a1.set_title("Turning the robot shifts the scan circularly")
    a1.legend(loc="lower right", fontsize=8, framealpha=0.9)
    a1.grid(alpha=0.3)
    a2.plot(u, spec[0], "-", color="tab:blue", lw=2.5, label="|DFT| of the scan")
    a2.plot(u, spec[1], "--", color="tab:orange", lw=1.2, label="|DFT| of the turned scan")
    a2.set_xscale("log")
    a2.set_yscale("log")
    a2.set_xlabel("frequency u (cycles per turn)")
    a2.set_ylabel("|DFT(u)| (m)")
    same = np.abs(spec[0] - spec[1]).max()
    a2.set_title(f"...and leaves |DFT| unchanged (largest difference {same:.1e} m)")
    a2.legend(loc="lower left", fontsize=8, framealpha=0.9)
    a2.grid(alpha=0.3, which="both")
    F0, F1 = np.fft.rfft(r), np.fft.rfft(turned)
    nshow = min(40, spec.shape[1])
    uu = np.arange(1, nshow + 1)
    dphase = np.angle(F1[1:nshow + 1] / F0[1:nshow + 1])
    expect = np.angle(np.exp(2j * np.pi * uu * k / B))
    a3.plot(uu, np.degrees(dphase), "o", color="tab:orange", ms=7, mfc="none", mew=1.5,
            label="phase of turned - phase of scan")
    a3.plot(uu, np.degrees(expect), "x", color="k", ms=5,
            label=f"2 pi u k / B with k = {k} beams (wrapped to +-180)")
    a3.set_xlabel("frequency u (cycles per turn)")
    a3.set_ylabel("phase difference (deg)")
    a3.set_ylim(-190, 190)
    a3.set_title("The turn is all in the phase, which |DFT| drops")
    a3.legend(loc="lower left", fontsize=8, framealpha=0.9)
    a3.grid(alpha=0.3)
    return fig
