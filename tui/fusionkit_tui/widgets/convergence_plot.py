"""A live plot of each PSO run's best cost per iteration (eq. 3's MSE, lower is better)."""

from __future__ import annotations

from textual_plotext import PlotextPlot

__all__ = ["ConvergencePlot", "MONO_MARKERS", "integer_ticks"]

#: Markers of the successive lines when there is no colour (``NO_COLOR``).
MONO_MARKERS = ("braille", "+", "x", "o", "*", "#", "@", "%")


def integer_ticks(lo: int, hi: int, most: int = 6) -> list[int]:
    """Ticks for an axis of whole numbers from ``lo`` to ``hi``: the multiples in that range
    of the least step of 1, 2 or 5 times a power of ten that gives at most ``most`` (at least
    2) of them; never a fraction (an iteration has no half)."""
    lo, hi = int(lo), int(hi)
    if hi <= lo:
        return [lo]
    most = max(int(most), 2)
    step, k = 1, 0
    while (hi // step) - (-(-lo // step)) + 1 > most:
        k += 1
        step = (1, 2, 5)[k % 3] * 10 ** (k // 3)
    return list(range(-(-lo // step) * step, hi + 1, step))


class ConvergencePlot(PlotextPlot):
    """One line per swarm (``"robot_2 -> robot_1"``, then its local refinement): the best cost
    after each iteration. Feed it with :meth:`start` and :meth:`add`; :meth:`reset` empties it.
    The legend is left to the caller (plotext's own would cover the lines)."""

    DEFAULT_CSS = """
    ConvergencePlot {
        height: 1fr;
        min-height: 6;
    }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self._series: list[tuple[str, list[int], list[float]]] = []
        self._colours: list[str | None] = []
        #: Shown as the title instead of the default one (e.g. why there is nothing to plot).
        self.note = ""

    @property
    def series(self) -> list[tuple[str, list[int], list[float]]]:
        """``(label, iterations, best costs)`` per swarm, in the order they ran."""
        return self._series

    @property
    def colours(self) -> list[str | None]:
        """The colour of each line (``"#rrggbb"``, None for plotext's own)."""
        return self._colours

    def reset(self, note: str = "") -> None:
        self._series, self._colours = [], []
        self.note = note
        self.refresh()

    def start(self, label: str, colour: str | None = None) -> None:
        """Begin a new line for the swarm ``label``, drawn in ``colour`` (``"#rrggbb"``)."""
        self._series.append((label, [], []))
        self._colours.append(colour)
        self.refresh()

    def add(self, iteration: int, best_cost: float) -> None:
        """Add the best cost after ``iteration`` to the current line."""
        if not self._series:
            self.start("")
        _, xs, ys = self._series[-1]
        xs.append(int(iteration))
        ys.append(float(best_cost))
        self.refresh()

    def render(self):
        plt = self.plt
        plt.clear_data()
        plt.clear_figure()
        plt.title(self.note or "PSO best cost per iteration (eq. 3 MSE)")
        plt.xlabel("iteration")
        drawn = False
        no_color = bool(getattr(self.app, "no_color", False))
        for k, ((label, xs, ys), colour) in enumerate(zip(self._series, self._colours)):
            if xs:
                # without colour, lines differ by their marker (in the legend's order)
                marker = MONO_MARKERS[k % len(MONO_MARKERS)] if no_color else "braille"
                rgb = None if colour is None else tuple(int(colour[i:i + 2], 16) for i in (1, 3, 5))
                if rgb is None or no_color:
                    plt.plot(xs, ys, marker=marker)
                else:
                    plt.plot(xs, ys, marker=marker, color=rgb)
                drawn = True
        if drawn:
            xs = [x for _, xs, _ in self._series for x in xs]
            plt.xticks(integer_ticks(min(xs), max(xs), self.size.width // 12))
        else:
            plt.xlim(0, 1)
            plt.ylim(0, 1)
        return super().render()
