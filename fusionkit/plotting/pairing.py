"""Pairing (the paper's eq. 2): Pearson's rho between robots, agreement counts, the fusion order,
matched poses.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..grid import OccupancyGrid
from .grids import _new_figure, plot_grid, robot_colour

__all__ = ["plot_rho_matrix", "agreement_curves", "plot_agreement_curves", "plot_counts",
           "plot_fusion_plan", "plot_rho_overview", "plot_pairing", "plot_matches"]


def _all_unique(unique_list) -> None:
    """Refuse a list with a map the paper's method left out unscanned (``MergeResult.unique``
    holds None for it): name it instead of failing on it."""
    gone = [k + 1 for k, u in enumerate(unique_list) if u is None]
    if gone:
        raise InputError(f"map{'s' if len(gone) > 1 else ''} {', '.join(map(str, gone))} "
                         f"{'have' if len(gone) > 1 else 'has'} no unique poses (left out of the "
                         "merge unscanned, see its reason); plot the others")


def plot_rho_matrix(ax, unique_list, names, *, theta: float | None = None, title: str | None = None):
    """Pearson's rho (eq. 2) between every two unique poses of all robots, as a heat map.

    The unique poses of robot 1 come first, then robot 2's, ...; thin lines separate the robots'
    blocks. With ``theta``, only the agreeing pairs (``rho > theta``) are coloured.

    Returns
    -------
    matplotlib.image.AxesImage
    """
    from ..pairing import pearson_matrix

    _all_unique(unique_list)
    spectra = [u.unique_spectra for u in unique_list]
    S = np.concatenate(spectra)
    rho = pearson_matrix(S, S)
    sizes = np.array([len(s) for s in spectra])
    edges = np.concatenate([[0], np.cumsum(sizes)])
    if theta is None:
        im = ax.imshow(rho, cmap="viridis", vmin=max(-1.0, float(np.percentile(rho, 1))), vmax=1.0,
                       interpolation="nearest", origin="upper")
        label = "Pearson rho (eq. 2)"
    else:
        shown = np.where(rho > theta, rho, np.nan)
        ax.set_facecolor("0.93")
        im = ax.imshow(shown, cmap="viridis", vmin=theta, vmax=1.0, interpolation="nearest",
                       origin="upper")
        label = f"rho of the agreeing pairs (rho > theta = {theta:g})"
    for e in edges[1:-1]:
        ax.axhline(e - 0.5, color="w", lw=1.2)
        ax.axvline(e - 0.5, color="w", lw=1.2)
    centres = (edges[:-1] + edges[1:]) / 2 - 0.5
    ax.set_xticks(centres, [f"{n}\n({s})" for n, s in zip(names, sizes)], fontsize=8)
    ax.set_yticks(centres, list(names), fontsize=8)
    ax.set_xlabel("unique pose (grouped by robot; count in brackets)")
    ax.set_ylabel("unique pose (grouped by robot)")
    ax.set_title(title if title is not None else label)
    cb = ax.figure.colorbar(im, ax=ax, shrink=0.85)
    cb.set_label(label)
    return im


def agreement_curves(unique_list, thetas):
    """Agreeing unique-pose pairs of every two robots as the threshold varies.

    Returns ``{(a, b): counts}`` with ``counts[i]`` the number of pairs with ``rho > thetas[i]``.
    """
    from ..pairing import agreement
    _all_unique(unique_list)

    out = {}
    t = np.asarray(thetas, float)
    for a in range(len(unique_list)):
        for b in range(a + 1, len(unique_list)):
            rho = agreement(unique_list[a].unique_spectra, unique_list[b].unique_spectra, 1.0).rho
            v = np.sort(rho.ravel())
            out[(a, b)] = v.size - np.searchsorted(v, t, side="right")
    return out


def plot_agreement_curves(ax, unique_list, names, theta: float, *, thetas=None):
    """How many unique-pose pairs of each two robots agree (rho > theta) as theta varies."""
    import matplotlib as mpl

    thetas = np.linspace(0.5, 0.995, 100) if thetas is None else np.asarray(thetas)
    curves = agreement_curves(unique_list, thetas)
    cmap = mpl.colormaps["tab10"]
    for i, ((a, b), c) in enumerate(curves.items()):
        ax.plot(thetas, np.maximum(c, 0.8), "-", color=cmap(i % 10), lw=1.3,
                label=f"{names[a]} ~ {names[b]}")
    ax.axvline(theta, color="k", ls="--", lw=1.0, label=f"theta = {theta:g}")
    ax.set_yscale("log")
    ax.set_xlabel("threshold theta on Pearson rho")
    ax.set_ylabel("agreeing unique-pose pairs (rho > theta)")
    ax.set_title("Agreement of each pair of robots against theta")
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9, ncol=2)
    ax.grid(alpha=0.3, which="both")


def plot_counts(ax, counts, names, *, title: str | None = None):
    """The agreement counts between every two robots as an annotated matrix."""
    c = np.asarray(counts)
    im = ax.imshow(c, cmap="Blues", interpolation="nearest")
    for i in range(c.shape[0]):
        for j in range(c.shape[1]):
            ax.text(j, i, "-" if i == j else f"{c[i, j]}", ha="center", va="center", fontsize=9,
                    color="w" if c[i, j] > 0.6 * max(c.max(), 1) else "k")
    ax.set_xticks(range(len(names)), names, rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.set_title(title if title is not None else "Agreeing unique-pose pairs (counts)")
    cb = ax.figure.colorbar(im, ax=ax, shrink=0.8)
    cb.set_label("pairs with rho > theta")


def plot_fusion_plan(ax, plan, names, *, title: str | None = None):
    """The fusion order as a graph: robots on a circle, grey edges as thick as their agreement
    count, and numbered arrows for the steps (from the placed map to the map that joins)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import FancyArrowPatch

    n = len(names)
    ang = np.pi / 2 - 2 * np.pi * np.arange(n) / n
    pos = np.column_stack([np.cos(ang), np.sin(ang)])
    c = np.asarray(plan.counts).copy()
    np.fill_diagonal(c, 0)
    cmax = max(int(c.max()), 1)
    for a in range(n):
        for b in range(a + 1, n):
            if c[a, b] > 0:
                ax.plot(*pos[[a, b]].T, "-", color="0.75", lw=1 + 7 * c[a, b] / cmax, zorder=1,
                        solid_capstyle="round")
                m = pos[[a, b]].mean(axis=0)
                ax.text(*m, f"{c[a, b]}", fontsize=8, color="0.35", ha="center", va="center",
                        bbox=dict(boxstyle="round,pad=0.15", fc="w", ec="none", alpha=0.8), zorder=2)
    bend = 0.2
    for i, (a, b) in enumerate(plan.steps):
        arr = FancyArrowPatch(pos[a], pos[b], arrowstyle="-|>", mutation_scale=18, lw=2.2,
                              color="tab:red", shrinkA=18, shrinkB=18, zorder=3,
                              connectionstyle=f"arc3,rad={bend}")
        ax.add_patch(arr)
        d = pos[b] - pos[a]
        side = np.array([d[1], -d[0]])  # the side matplotlib's arc3 bends to
        m = pos[[a, b]].mean(axis=0) + 0.5 * bend * side + 0.13 * side / max(np.hypot(*side), 1e-9)
        ax.text(*m, f"{i + 1}", fontsize=11, color="tab:red", weight="bold", ha="center",
                va="center", zorder=4)
    first = plan.steps[0][0] if plan.steps else None
    for k in range(n):
        unplaced = k in plan.unplaced
        ax.scatter(*pos[k], s=900, color="0.85" if unplaced else robot_colour(k),
                   edgecolors="k", linewidths=3 if k == first else 1, zorder=5)
        ax.text(*(pos[k] * 1.42), names[k], ha="center", va="center", fontsize=9)
        ax.text(*pos[k], f"{k + 1}", ha="center", va="center", fontsize=10, color="w",
                weight="bold", zorder=6)
    ax.set_xlim(-1.75, 1.75)
    ax.set_ylim(-1.75, 1.6)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_xlabel("(a graph: positions carry no units)")
    order = " -> ".join(names[k] for k in plan.order) if plan.steps else "none"
    ax.set_title(title if title is not None else f"Fusion order: {order}", fontsize=10)
    handles = [Line2D([], [], color="0.75", lw=4, label="agreement (width = count)"),
               Line2D([], [], color="tab:red", lw=2, marker=">", label="fusion step k: placed -> joins"),
               Line2D([], [], color="w", marker="o", mfc="w", mec="k", mew=3, ms=12, ls="",
                      label="first map (reference of the plan)")]
    if plan.unplaced:
        handles.append(Line2D([], [], color="w", marker="o", mfc="0.85", mec="k", ms=12, ls="",
                              label="agrees with no placed map"))
    ax.legend(handles=handles, loc="lower center", fontsize=7, framealpha=0.9,
              bbox_to_anchor=(0.5, -0.02), ncol=2)


def plot_rho_overview(unique_list, names, theta: float):
    """Pearson's rho between all unique poses (left) and only the pairs above ``theta``
    (right)."""
    fig = _new_figure(15.0, 6.4)
    a1, a2 = fig.subplots(1, 2)
    plot_rho_matrix(a1, unique_list, names, title="Pearson rho (eq. 2) of every two unique poses")
    plot_rho_matrix(a2, unique_list, names, theta=theta,
                    title=f"Agreeing pairs: rho > theta = {theta:g} (others grey)")
    return fig


def plot_pairing(unique_list, names, theta: float):
    """From agreement to fusion order at threshold ``theta``: the agreement of every pair of
    robots against theta (left), the counts at ``theta`` (middle) and the fusion order
    (right)."""
    from ..pairing import agreement, fusion_order

    _all_unique(unique_list)
    n = len(unique_list)
    counts = np.zeros((n, n), int)
    for a in range(n):
        for b in range(a + 1, n):
            c = agreement(unique_list[a].unique_spectra, unique_list[b].unique_spectra, theta).count
            counts[a, b] = counts[b, a] = c
    plan = fusion_order(counts)
    fig = _new_figure(17.0, 5.4)
    a1, a2, a3 = fig.subplots(1, 3, width_ratios=[1.2, 1.0, 1.0])
    plot_agreement_curves(a1, unique_list, names, theta)
    plot_counts(a2, counts, names, title=f"Agreeing pairs at theta = {theta:g}")
    plot_fusion_plan(a3, plan, names)
    return fig


def plot_matches(world: OccupancyGrid, poses_a, poses_b, *, tolerance: float = 1.0,
                 names=("a", "b"), title: str | None = None, max_lines: int = 400):
    """Agreeing unique-pose pairs drawn where they truly are in the world (for teaching: the
    merger never sees this): a line from robot a's pose to robot b's, green when the two poses
    are within ``tolerance`` m (the same place), red otherwise.

    Parameters
    ----------
    world : OccupancyGrid
    poses_a, poses_b : (M, 2 or 3) array
        True world positions of the two poses of each agreeing pair.
    tolerance : float
        Distance (m) under which a pair counts as the same place.
    names : (str, str)
    title : str, optional
    max_lines : int
        At most this many red lines are drawn (an even subsample); the counts use all pairs.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.lines import Line2D

    def xy(p):
        a = np.asarray(p, float)
        return a[:, :2] if a.ndim == 2 and len(a) else np.zeros((0, 2))

    pa, pb = xy(poses_a), xy(poses_b)
    if len(pa) != len(pb):
        raise InputError(f"poses_a and poses_b must pair up, got {len(pa)} and {len(pb)} poses")
    d = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])
    good = d < tolerance
    fig = _new_figure(10.0, 7.0)
    ax = fig.subplots()
    plot_grid(ax, world, title="", alpha=0.6)
    bad = np.flatnonzero(~good)
    if bad.size > max_lines:
        bad = bad[np.linspace(0, bad.size - 1, max_lines).round().astype(int)]
    for i in bad:
        ax.plot(*np.stack([pa[i], pb[i]]).T, "-", color="tab:red", lw=0.4, alpha=0.35)
    for i in np.flatnonzero(good):
        ax.plot(*np.stack([pa[i], pb[i]]).T, "-", color="tab:green", lw=1.2, alpha=0.9)
    ax.plot(pb[good, 0], pb[good, 1], "o", color="tab:green", ms=3)
    frac = float(good.mean()) if len(d) else 0.0
    ax.set_title(title if title is not None else
                 f"{len(d)} agreeing pairs {names[0]} ~ {names[1]}, at their true places: "
                 f"{int(good.sum())} ({100 * frac:.0f}%) are the same place", fontsize=10)
    ax.legend(handles=[Line2D([], [], color="tab:green", lw=1.5,
                              label=f"same place (< {tolerance:g} m apart)"),
                       Line2D([], [], color="tab:red", lw=1, alpha=0.6,
                              label="alike, but different places" +
                                    (f" ({max_lines} of {int((~good).sum())} drawn)"
                                     if (~good).sum() > max_lines else ""))],
              loc="upper right", fontsize=8, framealpha=0.9)
    return fig
