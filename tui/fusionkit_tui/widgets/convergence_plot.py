"""A live plot of each PSO run's best cost per iteration (eq. 3's MSE, lower is better)."""

from __future__ import annotations

from textual_plotext import PlotextPlot

__all__ = ["ConvergencePlot"]


class ConvergencePlot(PlotextPlot):
    """One line per alignment (``"robot_2 -> robot_1"``): the swarm's best cost after each
    iteration. Feed it with :meth:`start` and :meth:`add`; :meth:`reset` empties it."""

    DEFAULT_CSS = """
    ConvergencePlot {
        height: 1fr;
        min-height: 6;
    }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self._series: list[tuple[str, list[int], list[float]]] = []

    @property
    def series(self) -> list[tuple[str, list[int], list[float]]]:
        """``(label, iterations, best costs)`` per alignment, in the order they ran."""
        return self._series

    def reset(self) -> None:
        self._series = []
        self.refresh()

    def start(self, label: str) -> None:
        """Begin a new line for the alignment ``label``."""
        self._series.append((label, [], []))
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
        plt.title("PSO best cost per iteration (eq. 3 MSE)")
        plt.xlabel("iteration")
        drawn = False
        for label, xs, ys in self._series:
            if xs:
                plt.plot(xs, ys, label=label, marker="braille")
                drawn = True
        if not drawn:
            plt.xlim(0, 1)
            plt.ylim(0, 1)
        return super().render()
