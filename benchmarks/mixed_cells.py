"""Does the decision on two maps of different cell sizes depend on which is the reference?
Pairs of windows of real floors, the second window drawn at twice the cell size (a coarse cell
a wall when one of its four is, as a mapper at that cell size draws it), each pair merged with
either map as the reference, as shipped (the maps compared at the finest cell size,
:func:`fusionkit._merge_inputs._compared`), at the coarsest, and at the reference's cell size
(the code before), in the same process; and pairs of windows of two floors (a fine window of one
with a coarse window of another), each merged both ways round::

    python benchmarks/mixed_cells.py --maps ../shared/maps/real --pairs 3 --seed 1

Prints, per way and per reference, the pairs placed within 3 coarse cells and 2 degrees of the
truth / elsewhere / refused, how many pairs got the same decision both ways round, how many
pairs of two floors were merged (every one wrong), and the median seconds of a merge with the
coarse map as the reference (only comparable within the run).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE))

import fusionkit.pipeline as pipeline  # noqa: E402
from fusionkit.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid  # noqa: E402
from fusionkit.mapio import load_map  # noqa: E402
from fusionkit.methods.peers import crop_pair, placement_error  # noqa: E402

SHIPPED = pipeline._compared


def coarser(grid: OccupancyGrid) -> OccupancyGrid:
    """``grid`` at twice its cell size, a coarse cell a wall when one of its four is."""
    t = grid.trinary()
    h, w = t.shape[0] // 2 * 2, t.shape[1] // 2 * 2
    blocks = t[:h, :w].reshape(h // 2, 2, w // 2, 2)
    data = np.where((blocks == OCCUPIED).any(axis=(1, 3)), OCCUPIED,
                    np.where((blocks != UNKNOWN).any(axis=(1, 3)), FREE, UNKNOWN))
    return OccupancyGrid(data.astype(np.int8), 2 * grid.resolution, grid.origin)


def outcome(result, invert: bool, truth, moving, bound: float) -> str:
    p = result.placements[1]
    if not p.merged:
        return "refused"
    # the second map's placement in the first's frame; the truth is of the coarse map into the
    # fine one's
    est = p.transform.inverse if invert else p.transform
    d, th = placement_error(est, truth, moving)
    return "right" if d < bound and th < math.radians(2) else "wrong"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--maps", default=str(HERE.parent / "shared" / "maps" / "real"))
    ap.add_argument("--pairs", type=int, default=3, help="window pairs per floor")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    cases = []
    for f in sorted(Path(args.maps).glob("*.yaml")):
        g = load_map(f)
        for _ in range(args.pairs):
            size = int(rng.integers(100, 241))
            try:
                c = crop_pair(g, rng, size=size, min_overlap=0.4, min_occupied=100)
            except Exception:   # noqa: BLE001 - a floor with no such window: none drawn there
                continue
            cases.append((f.stem, c.a, coarser(c.b), c.truth))
    n = len(cases)
    # a fine window of one floor with the coarse window drawn seven pairs later, of another floor
    negatives = [(cases[i][1], cases[(i + 7) % n][2]) for i in range(n)
                 if cases[i][0] != cases[(i + 7) % n][0]]
    print(f"{n} pairs of windows of {args.maps}, the second at twice the cell size; "
          f"{len(negatives)} pairs of windows of two floors")
    print("| compared at | fine map the reference: right / wrong / refused | coarse map the "
          "reference | same decision both ways | two floors merged (fine ref, coarse ref) | median s "
          "per merge, coarse map the reference |")
    print("|---|---|---|---|---|---|")

    def finest(o, at_ref, ref):
        return pipeline._same_resolution(o, min(range(len(o)), key=lambda k: o[k].resolution))

    def coarsest(o, at_ref, ref):
        return pipeline._same_resolution(o, max(range(len(o)), key=lambda k: o[k].resolution))

    config = pipeline.MergeConfig(seed=args.seed)
    for name, compared in (("the finest cell size (shipped)", SHIPPED),
                           ("the coarsest cell size", coarsest),
                           ("the reference's cell size (before)", lambda o, at_ref, ref: at_ref)):
        pipeline._compared = compared
        fine_ref, coarse_ref, same, seconds = [], [], 0, []
        for world, a, b, truth in cases:
            bound = 3 * b.resolution
            o1 = outcome(pipeline.merge([a, b], config=config), False, truth, b, bound)
            t0 = time.perf_counter()
            r2 = pipeline.merge([b, a], config=config)
            seconds.append(time.perf_counter() - t0)
            o2 = outcome(r2, True, truth, b, bound)
            fine_ref.append(o1)
            coarse_ref.append(o2)
            same += (o1 == "refused") == (o2 == "refused")
        wrong = [sum(pipeline.merge(pair, config=config).placements[1].merged for pair in
                     (negatives if way == 0 else [(b, a) for a, b in negatives])) for way in (0, 1)]
        pipeline._compared = SHIPPED

        def counts(outs):
            return " / ".join(str(outs.count(w)) for w in ("right", "wrong", "refused"))
        print(f"| {name} | {counts(fine_ref)} | {counts(coarse_ref)} | {same} / {n} | "
              f"{wrong[0]}, {wrong[1]} of {len(negatives)} | {float(np.median(seconds)):.3f} |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
