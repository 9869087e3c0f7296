"""``python -m fusionkit.worlds``: write the default simulation worlds as map_server maps."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import FusionkitError
from ..mapio import save_map
from ..worlds import DEFAULT_RESOLUTION, DEFAULT_SIZE, WORLDS, make_world


def main(argv=None) -> int:
    """Write the chosen worlds as ``OUT/NAME.yaml`` + ``OUT/NAME.pgm``; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog="python -m fusionkit.worlds",
        description="Write the simulation worlds as ROS map_server maps (NAME.yaml + NAME.pgm). "
                    "With the defaults this regenerates the repository's maps/ directory.")
    parser.add_argument("--out", default="maps",
                        help="output directory, created if missing (default: maps)")
    parser.add_argument("--seed", type=int, default=0, help="layout seed (default: 0)")
    parser.add_argument("--size", type=float, nargs=2, metavar=("W", "H"), default=DEFAULT_SIZE,
                        help="world width and height in metres (default: %(default)s)")
    parser.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION,
                        help="cell size in metres (default: %(default)s)")
    parser.add_argument("--kinds", nargs="+", choices=list(WORLDS), default=list(WORLDS),
                        help="which worlds to write (default: all)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        for kind in args.kinds:
            grid = make_world(kind, args.seed, args.size, args.resolution)
            save_map(grid, out / f"{kind}.yaml")
            c = grid.counts()
            print(f"{out / (kind + '.yaml')}: {grid.cols} x {grid.rows} cells at "
                  f"{grid.resolution:g} m, {c['free']} free, {c['occupied']} occupied")
    except FusionkitError as exc:
        print(f"python -m fusionkit.worlds: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"python -m fusionkit.worlds: error: {out}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    return 0
