"""Matplotlib figures of grids, trajectories, simulations and every step of the method.

Every function draws on axes or returns a :class:`matplotlib.figure.Figure`; nothing is shown or
saved here, so the same calls work in notebooks, scripts and tests (with the Agg backend).
Grids are drawn in metres with the map-server palette: occupied black, free white, unknown grey.
Robot ``k`` has the colour ``robot_colour(k)`` in every figure.

The figures of the notebooks, in the order of the method: scans (:func:`plot_scan`,
:func:`plot_drift`), unique poses (:func:`plot_section_spectra`, :func:`plot_unique_summary`,
:func:`plot_rotation_invariance`), pairing (:func:`plot_rho_overview`, :func:`plot_pairing`,
:func:`plot_matches`), alignment (:func:`cost_surface`, :func:`plot_swarm_snapshots`,
:func:`plot_pso_run`), fusion and metrics (:func:`plot_fused`, :func:`plot_fusion_steps`,
:func:`plot_table1`) and benchmarks (:func:`plot_bench_case`, :func:`plot_bench_summary`).

Modules, by the stage they draw:

* :mod:`.grids`: a grid in metres, the robots' colours, the legend of cell states;
* :mod:`.world`: the world and the robots (simulation, scans, odometry drift, worlds);
* :mod:`.unique`: unique poses (Algorithm 1, eq. 1);
* :mod:`.pairing`: pairing and the fusion order (eq. 2);
* :mod:`.alignment`: the PSO alignment (eqs. 3-4);
* :mod:`.fusion`: fusion and Table 1 metrics (Section 3.6);
* :mod:`.bench`: benchmark cases and summaries.

Every public name is also importable from :mod:`fusionkit.plotting` itself.
"""

from __future__ import annotations

from .grids import ROBOT_COLOURS, grid_image, plot_grid, robot_colour, state_legend, owner_image
from .world import plot_simulation, plot_scan, plot_drift, plot_worlds
from .unique import (plot_section_spectra, plot_divergence, plot_unique_poses, plot_unique_summary,
                     plot_unique_in_world, plot_rotation_invariance)
from .pairing import (plot_rho_matrix, agreement_curves, plot_agreement_curves, plot_counts,
                      plot_fusion_plan, plot_rho_overview, plot_pairing, plot_matches)
from .alignment import (CostSurface, cost_surface, plot_cost_surface, plot_swarm, plot_surfaces,
                        plot_swarm_snapshots, plot_pso_run, plot_convergence, plot_masks,
                        plot_mask_panels)
from .fusion import (plot_fused, plot_merge, plot_cells, plot_cell_fusion, plot_fusion_steps,
                     plot_table1)
from .bench import plot_case, plot_on_truth, plot_bench_case, plot_bench_summary

__all__ = ["plot_grid", "plot_simulation", "grid_image", "ROBOT_COLOURS", "robot_colour",
           "owner_image", "plot_fused", "plot_merge", "plot_scan", "plot_drift",
           "plot_section_spectra", "plot_divergence", "plot_unique_poses", "plot_unique_summary",
           "plot_rotation_invariance", "plot_rho_matrix", "agreement_curves",
           "plot_agreement_curves", "plot_counts", "plot_fusion_plan", "plot_matches",
           "CostSurface", "cost_surface", "plot_cost_surface", "plot_swarm",
           "plot_swarm_snapshots", "plot_convergence", "plot_masks", "plot_cells",
           "plot_cell_fusion", "plot_fusion_steps", "plot_table1", "state_legend", "plot_worlds",
           "plot_unique_in_world", "plot_rho_overview", "plot_pairing", "plot_surfaces",
           "plot_pso_run", "plot_mask_panels", "plot_case", "plot_on_truth", "plot_bench_case",
           "plot_bench_summary"]
