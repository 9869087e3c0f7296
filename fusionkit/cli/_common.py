"""Helpers shared by the subcommands: progress bars, argument types."""

from __future__ import annotations

import argparse
import math
import sys
import textwrap
import time


class Progress:
    """A one-line progress bar on stderr, drawn only when stderr is a terminal.

    Call it as ``progress(done, total, label)``; it redraws at most 10 times a second.
    """

    def __init__(self, title: str, stream=None, enabled: bool | None = None):
        self.title = title
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self._last = 0.0
        self._t0 = time.perf_counter()
        self._drawn = False

    def __call__(self, done: int, total: int, label: str = "") -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if done < total and now - self._last < 0.1:
            return
        self._last = now
        frac = 0.0 if total <= 0 else min(1.0, done / total)
        width = 28
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        text = f"\r{self.title} [{bar}] {100 * frac:5.1f}% {label}"[:120]
        self.stream.write(text.ljust(100))
        self.stream.flush()
        self._drawn = True

    def close(self) -> None:
        if self.enabled and self._drawn:
            self.stream.write(f"\r{self.title}: done in {time.perf_counter() - self._t0:.1f} s".ljust(100) + "\n")
            self.stream.flush()


def paragraphs(*paras: str) -> str:
    """Help text of several paragraphs, each wrapped to 88 columns."""
    return "\n\n".join(textwrap.fill(p, 88) for p in paras)


def int_range(lo: int, hi: int):
    """argparse type: an integer in ``[lo, hi]``."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"must be between {lo} and {hi}, got {v}")
        return v
    return parse


def float_range(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False):
    """argparse type: a float in ``[lo, hi]`` (``lo_open``, ``hi_open``: that end left out)."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not (v > lo if lo_open else v >= lo) or not (v < hi if hi_open else v <= hi):
            raise argparse.ArgumentTypeError(
                f"must be {'>' if lo_open else '>='} {lo:g} and {'<' if hi_open else '<='} {hi:g}, "
                f"got {v:g}")
        return v
    return parse


def add_merge_options(p, method: str | None = None, *, seed_flag: str = "--seed") -> None:
    """The method's settings, shared by ``merge`` and ``run`` (``method``: the command's default
    method, if not the library's; ``seed_flag``: the option that sets the merge's seed)."""
    from ..pipeline import METHODS, MergeConfig
    d = MergeConfig()
    method = method or d.method
    g = p.add_argument_group("method settings")
    g.add_argument("--method", choices=METHODS, default=method,
                   help=f"merging method (default {method}). consensus: hypotheses from scans "
                        f"and walls, each verified on the whole maps, kept consistent over all "
                        f"maps, refused when unsure; spectral-pso: the paper's DFT + Pearson + PSO "
                        f"(the settings below are its own); map-merge, map-merge-shipped, "
                        f"hough-spectrum, fourier-mellin: the classic peers")
    g.add_argument("--max-false-merge", type=float_range(0, 1, lo_open=True, hi_open=True), default=d.max_false_merge,
                   metavar="RISK",
                   help=f"consensus: the false-merge risk accepted, the expected number of wrong "
                        f"placements that would fit as well as one accepted (default "
                        f"{d.max_false_merge:g}; above 0 and below 1, smaller is safer and merges less)")
    g.add_argument(seed_flag, dest="seed", type=int_range(0, 2**63 - 1), default=d.seed,
                   help=f"seed of every random step{' of the merge' if seed_flag != '--seed' else ''} "
                        f"(default {d.seed})")
    g.add_argument("--theta", type=float_range(-1, 1), default=d.theta,
                   help=f"Pearson rho above which two unique poses agree (eq. 2; default {d.theta})")
    g.add_argument("--unique-count", type=int_range(1, 100000), default=d.unique_count,
                   help=f"unique poses per robot; delta is set to give this many "
                        f"(Algorithm 1; default {d.unique_count})")
    g.add_argument("--delta", type=float_range(0, math.inf), default=None,
                   help="fixed divergence threshold of Algorithm 1 (spectrum units: m x beams); "
                        "overrides --unique-count")
    g.add_argument("--sub-sec", type=int_range(1, 1000), default=d.sub_sec,
                   help=f"half-width of Algorithm 1's sections in poses (default {d.sub_sec})")
    g.add_argument("--particles", type=int_range(1, 10000), default=d.pso.particles,
                   help=f"PSO swarm size (default {d.pso.particles})")
    g.add_argument("--iterations", type=int_range(0, 100000), default=d.pso.iterations,
                   help=f"PSO iterations (default {d.pso.iterations}; 0: the best particle of "
                        f"the starting swarm, not moved)")
    g.add_argument("--w", type=float_range(0, 10), default=d.pso.w, help=f"PSO inertia weight (default {d.pso.w})")
    g.add_argument("--c1", type=float_range(0, 10), default=d.pso.c1,
                   help=f"PSO cognitive coefficient (default {d.pso.c1})")
    g.add_argument("--c2", type=float_range(0, 10), default=d.pso.c2,
                   help=f"PSO social coefficient (default {d.pso.c2})")
    g.add_argument("--accept", type=float_range(0, 1), default=d.accept,
                   help=f"least fraction of a map's walls that must fall on the fused map's walls for "
                        f"it to be merged (default {d.accept})")
    g.add_argument("--no-seeding", action="store_true",
                   help="start the swarm at random only (the paper's blind search) instead of also "
                        "at the transforms given by matched scans")


def merge_config_from_args(args, *, reference: int = 0):
    """A MergeConfig from the options of :func:`add_merge_options`."""
    from dataclasses import replace
    from ..pipeline import MergeConfig
    cfg = MergeConfig(method=args.method, theta=args.theta, unique_count=args.unique_count,
                      delta=args.delta, sub_sec=args.sub_sec, accept=args.accept,
                      reference=reference, seed=args.seed, max_false_merge=args.max_false_merge)
    cfg = cfg.with_pso(particles=args.particles, iterations=args.iterations, w=args.w,
                       c1=args.c1, c2=args.c2)
    if args.no_seeding:
        cfg = replace(cfg, alignment=replace(cfg.alignment, seeded=False))
    return cfg
