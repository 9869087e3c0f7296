"""fusionkit: multi-robot occupancy-grid map fusion for collaborative SLAM.

The paper's method, "Map Fusion for Precise Yet Efficient Collaborative SLAM" (``method=
"spectral-pso"``): unique poses by the DFT of the scans (Algorithm 1), the fusion order by
Pearson correlation of their spectra (eq. 2), the alignment by Particle Swarm Optimization of a
mask MSE (eq. 3), then transform (eq. 4) and fusion (Section 3.6), measured by the paper's
Table 1 metrics. The default method, ``"consensus"`` (:mod:`fusionkit.methods.consensus`),
builds on it: placements from every scan and from the walls, each verified on the whole maps,
kept consistent over all maps, and refused when not sure. The classic peers are in
:mod:`fusionkit.methods.peers`.

The paper's Fig. 1 in modules (``fusionkit/README.md`` has the whole map): unique poses, eq. 1
:mod:`fusionkit.unique_poses`; pairing, eq. 2 :mod:`fusionkit.pairing`; the eq. 3 objective
:mod:`fusionkit.alignment` (swarm: :mod:`fusionkit.pso`); the eq. 4 transform
:mod:`fusionkit.transform` and :mod:`fusionkit.resample`; fusion (3.6) :mod:`fusionkit.fusion`;
Table 1 :mod:`fusionkit.metrics`. :func:`merge` (:mod:`fusionkit.pipeline`) runs a method of
:mod:`fusionkit.methods` (the paper's: :mod:`fusionkit.methods.paper`) and fuses its placements.

Quick start::

    import fusionkit as fk
    sim = fk.simulate(fk.default_world(), fk.SimulationConfig(robots=3, poses=1500, seed=1))
    result = fk.merge([r.grid for r in sim.robots], scans=[r.scans for r in sim.robots])
    fk.evaluate_map(result.grid, sim.world, sim.robots[0].transform)
"""

from __future__ import annotations

import os as _os
import signal as _signal
import sys as _sys


def _stopped_while_loading(signum, frame):
    """A Ctrl-C while the ``fusionkit`` program's modules load, before its command's handler
    is in place: one line and exit 130, not a traceback out of an import."""
    try:
        named = _sys.modules["fusionkit.cli"]._named(_sys.argv[1:])
    except Exception:   # noqa: BLE001 - the command line is not loaded that far: the program alone
        named = None
    _sys.stderr.write(f"fusionkit{' ' + named if named else ''}: interrupted; no output was left "
                      f"half-written\n")
    raise SystemExit(130)


# first of all, and only in the program itself (not in a Python session that imports fusionkit)
if _os.path.basename(_sys.argv[0] if _sys.argv else "") == "fusionkit" \
        and _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler:
    try:
        _signal.signal(_signal.SIGINT, _stopped_while_loading)
    except ValueError:   # not the main thread
        pass

__version__ = "0.1.0"

import importlib as _importlib  # noqa: E402

# Public names and the module that defines each. They are imported on first use, so that a
# command or script pays only for the parts it touches (numba, scipy and OpenCV load slowly).
_EXPORTS = {
    **dict.fromkeys(['FusionkitError', 'InputError', 'MapFormatError', 'ScanLogError'], "errors"),
    **dict.fromkeys(['FREE', 'OCCUPIED', 'UNKNOWN', 'OccupancyGrid'], "grid"),
    **dict.fromkeys(['Transform2D'], "transform"),
    **dict.fromkeys(['ScanLog', 'load_scans', 'save_scans', 'scans_path_for'], "scanlog"),
    **dict.fromkeys(['load_map', 'map_info', 'save_map'], "mapio"),
    **dict.fromkeys(['MappingConfig', 'build_grid'], "mapping"),
    **dict.fromkeys(['canvas_for', 'resample'], "resample"),
    **dict.fromkeys(['default_world', 'make_world'], "worlds"),
    **dict.fromkeys(['LidarConfig', 'MotionConfig', 'Simulation', 'SimulationConfig', 'simulate', 'write_run'], "simulate"),
    **dict.fromkeys(['UniquePoses', 'find_unique_poses', 'scan_spectra'], "unique_poses"),
    **dict.fromkeys(['agreement', 'fusion_order', 'pearson_matrix'], "pairing"),
    **dict.fromkeys(['PSOConfig', 'PSOResult', 'pso_minimize'], "pso"),
    **dict.fromkeys(['AlignmentConfig', 'align_points', 'overlap_score'], "alignment"),
    **dict.fromkeys(['FusedMap', 'fuse_cells', 'fuse_maps'], "fusion"),
    **dict.fromkeys(['MapMetrics', 'evaluate_map', 'table1'], "metrics"),
    **dict.fromkeys(['METHODS', 'MergeCancelled', 'MergeConfig', 'MergeEvent', 'MergeResult', 'merge'], "pipeline"),
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'fusionkit' has no attribute {name!r}")
    value = getattr(_importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    # the public names and the modules loaded so far, not this module's own helpers
    public = {n for n in set(globals()) | set(_EXPORTS) if not n.startswith("_")} - {"annotations"}
    return sorted(public | {"__version__", "__doc__"})
