"""Alignment by PSO (the paper's eqs. 3-4): cost surfaces, the swarm, convergence, masks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .grids import _new_figure

__all__ = ["CostSurface", "cost_surface", "plot_cost_surface", "plot_swarm", "plot_surfaces",
           "plot_swarm_snapshots", "plot_pso_run", "plot_convergence", "plot_masks",
           "plot_mask_panels"]


@dataclass(frozen=True, eq=False)
class CostSurface:
    """The eq. 3 objective over a ``(dx, dy)`` grid at one ``dphi`` (for drawing).

    ``dx`` (nx,) and ``dy`` (ny,) in metres, ``dphi`` in radians, ``cost`` (ny, nx)."""

    dx: np.ndarray
    dy: np.ndarray
    dphi: float
    cost: np.ndarray

    @property
    def extent(self) -> tuple[float, float, float, float]:
        hx = (self.dx[1] - self.dx[0]) / 2 if self.dx.size > 1 else 0.5
        hy = (self.dy[1] - self.dy[0]) / 2 if self.dy.size > 1 else 0.5
        return (self.dx[0] - hx, self.dx[-1] + hx, self.dy[0] - hy, self.dy[-1] + hy)


def cost_surface(field, moving, dphi: float, *, center=(0.0, 0.0), half_width: float = 10.0,
                 n: int = 121) -> CostSurface:
    """Evaluate eq. 3 (:func:`~fusionkit.alignment.mse_cost`) on an ``n x n`` grid of
    ``(dx, dy)`` around ``center`` (m) at a fixed ``dphi`` (rad)."""
    from ..alignment import mse_cost

    dx = center[0] + np.linspace(-half_width, half_width, n)
    dy = center[1] + np.linspace(-half_width, half_width, n)
    X, Y = np.meshgrid(dx, dy)
    params = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, float(dphi))])
    return CostSurface(dx, dy, float(dphi), mse_cost(field, moving, params).reshape(X.shape))


def plot_cost_surface(ax, surface: CostSurface, *, truth=None, colorbar: bool = True,
                      title: str | None = None):
    """Draw a :class:`CostSurface` (low cost dark), with the true ``(dx, dy)`` starred."""
    im = ax.imshow(surface.cost, origin="lower", extent=surface.extent, cmap="magma",
                   interpolation="nearest", aspect="equal")
    if truth is not None:
        ax.plot(truth[0], truth[1], "*", color="cyan", mec="k", ms=16, label="true (dx, dy)")
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_xlabel("dx (m)")
    ax.set_ylabel("dy (m)")
    ax.set_title(title if title is not None else
                 f"MSE of the masks (eq. 3) at dphi = {np.degrees(surface.dphi):.1f} deg")
    if colorbar:
        cb = ax.figure.colorbar(im, ax=ax, shrink=0.85)
        cb.set_label("MSE (eq. 3)")
    return im


def plot_swarm(ax, surface: CostSurface, positions, *, best=None, truth=None,
               iteration: int | None = None, colorbar: bool = False):
    """The swarm over the cost surface: each particle at its ``(dx, dy)``, coloured by how far
    its ``dphi`` is from the surface's (the surface is one slice of the 3-D search space).

    ``colorbar`` adds the particles' colour scale to the axes. Returns the particles'
    ``PathCollection`` (for a colour bar shared by several axes)."""
    from matplotlib.lines import Line2D

    plot_cost_surface(ax, surface, colorbar=False, title="")
    p = np.asarray(positions, float)
    off = np.degrees(np.abs((p[:, 2] - surface.dphi + np.pi) % (2 * np.pi) - np.pi))
    sc = ax.scatter(p[:, 0], p[:, 1], c=off, cmap="winter_r", vmin=0, vmax=180, s=26,
                    edgecolors="w", linewidths=0.6, zorder=3)
    if colorbar:
        cb = ax.figure.colorbar(sc, ax=ax, shrink=0.85)
        cb.set_label("particle's dphi off the slice's (deg)")
    handles = [Line2D([], [], marker="o", color="w", mfc="tab:green", mec="w", ls="", ms=6,
                      label="particle")]
    if best is not None:
        ax.plot(best[0], best[1], "P", color="w", mec="k", ms=13, zorder=4)
        handles.append(Line2D([], [], marker="P", color="w", mec="k", ls="", ms=10,
                              label="swarm's best so far"))
    if truth is not None:
        ax.plot(truth[0], truth[1], "*", color="cyan", mec="k", ms=15, zorder=4)
        handles.append(Line2D([], [], marker="*", color="cyan", mec="k", ls="", ms=12,
                              label="true (dx, dy)"))
    ax.set_xlim(surface.extent[:2])
    ax.set_ylim(surface.extent[2:])
    ax.set_title("swarm" if iteration is None else f"iteration {iteration}")
    ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.9)
    return sc


def plot_surfaces(surfaces, *, truth=None, titles=None):
    """Several :class:`CostSurface` side by side (for example the whole search box and a zoom
    on the true alignment)."""
    surfaces = list(surfaces)
    fig = _new_figure(7.0 * len(surfaces), 5.6)
    axes = np.atleast_1d(fig.subplots(1, len(surfaces)))
    for i, (ax, sf) in enumerate(zip(axes, surfaces)):
        plot_cost_surface(ax, sf, truth=truth, title=None if titles is None else titles[i])
    return fig


def _state_at(states, iteration: int):
    for st in states:
        if st.iteration == iteration:
            return st
    raise InputError(f"no swarm state of iteration {iteration}; recorded iterations are "
                     f"{states[0].iteration}..{states[-1].iteration}")


def plot_swarm_snapshots(surface: CostSurface, states, iterations, *, truth=None,
                         title: str | None = None):
    """The swarm at a few iterations, side by side.

    Parameters
    ----------
    surface : CostSurface
    states : sequence of PSOState
        The swarm after each iteration, as a PSO callback receives it.
    iterations : sequence of int
        Which iterations to draw.
    truth : (dx, dy), optional
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    its = [int(i) for i in iterations]
    cols = min(len(its), 3)
    rows = int(np.ceil(len(its) / cols))
    size = 4.6 if len(its) > 1 else 6.0
    fig = _new_figure(size * cols + 1.0, size * 0.95 * rows + 0.5)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, i in zip(axes, its):
        st = _state_at(states, i)
        sc = plot_swarm(ax, surface, st.positions, best=st.best_position, truth=truth, iteration=i)
        ax.set_title(f"iteration {i}: best MSE {st.best_cost:.4f}", fontsize=9)
        if ax is not axes[0]:
            ax.get_legend().remove()
    for ax in axes[len(its):]:
        ax.set_visible(False)
    cb = fig.colorbar(sc, ax=list(axes[: len(its)]), shrink=0.8, aspect=30)
    cb.set_label("particle's dphi off the slice's (deg)")
    fig.suptitle(title if title is not None else
                 f"The swarm over the MSE surface at dphi = {np.degrees(surface.dphi):.1f} deg")
    return fig


def plot_pso_run(surface: CostSurface, states, alignment, reference, moving, *, truth=None,
                 true_cost: float | None = None):
    """One alignment by PSO: the final swarm over the cost surface, the convergence curve and
    the masks aligned by the result.

    Parameters
    ----------
    surface : CostSurface
    states : sequence of PSOState
        The swarm after each iteration (from the callback).
    alignment : Alignment
        The result of :func:`~fusionkit.alignment.align_points`.
    reference, moving : (K, 2), (L, 2) arrays
        The masks' points (m), each in its own frame.
    truth : Transform2D, optional
        The true transform moving -> reference.
    true_cost : float, optional
        The MSE at the true alignment, drawn on the convergence curve.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = _new_figure(17.0, 5.3)
    a1, a2, a3 = fig.subplots(1, 3)
    last = states[-1]
    t_xy = None if truth is None else truth.to_paper()[:2]
    plot_swarm(a1, surface, last.positions, best=last.best_position, truth=t_xy, colorbar=True)
    a1.set_title(f"swarm after {last.iteration} iterations ({len(last.positions)} particles)",
                 fontsize=10)
    plot_convergence(a2, {"best MSE of this run": alignment.pso})
    if true_cost is not None:
        a2.axhline(true_cost, color="k", ls="--", lw=1.0, label="MSE at the true alignment")
        a2.legend(loc="upper right", fontsize=8, framealpha=0.9)
    title = "Masks aligned by the swarm's best"
    if truth is not None:
        dt, dr = alignment.transform.error_to(truth)
        title += f"\nerror {dt:.2f} m, {np.degrees(dr):.1f} deg from the truth"
    plot_masks(a3, reference, moving, alignment.transform, title=title)
    return fig


def plot_convergence(ax, runs, *, title: str | None = None):
    """Best cost against iteration for one or more PSO runs.

    ``runs`` maps a label to a :class:`~fusionkit.pso.PSOResult` or a history array."""
    for i, (label, r) in enumerate(dict(runs).items()):
        h = np.asarray(getattr(r, "history", r), float)
        ax.plot(np.arange(h.size), h, "-", lw=1.5, label=label, color=f"C{i}")
    ax.set_xlabel("iteration")
    ax.set_ylabel("best MSE so far (eq. 3)")
    ax.set_title(title if title is not None else "Convergence of the swarm")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)


def plot_masks(ax, reference, moving, transform=None, *, names=("reference", "moving"),
               colours=("tab:blue", "tab:red"), title: str | None = None):
    """The two masks (scan end points of the matched unique poses) in the reference frame,
    the moving one moved by ``transform`` (m)."""
    ref = np.asarray(reference, float)
    mov = np.asarray(moving, float)
    if transform is not None:
        mov = transform(mov)
    ax.plot(ref[:, 0], ref[:, 1], ".", color=colours[0], ms=1.5, alpha=0.6,
            label=f"{names[0]} mask ({len(ref)} points)")
    ax.plot(mov[:, 0], mov[:, 1], ".", color=colours[1], ms=1.5, alpha=0.6,
            label=f"{names[1]} mask ({len(mov)} points)")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, reference frame)")
    ax.set_ylabel("y (m, reference frame)")
    ax.set_title(title if title is not None else "Masks")
    leg = ax.legend(loc="upper right", fontsize=8, framealpha=0.9, markerscale=6)
    return leg


def plot_mask_panels(reference, moving, transforms, *, names=("reference", "moving")):
    """The two masks overlaid once per entry of ``transforms`` (``{panel title: Transform2D or
    None}``; None draws the moving mask as recorded, in its own frame)."""
    items = list(dict(transforms).items())
    fig = _new_figure(6.6 * len(items), 6.0)
    axes = np.atleast_1d(fig.subplots(1, len(items)))
    for ax, (title, t) in zip(axes, items):
        plot_masks(ax, reference, moving, t, names=names, title=title)
    return fig
