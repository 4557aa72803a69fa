"""The engineering answers of a posterior: :class:`EngineeringAnswers`, the typed content of
``answers.json`` (``bayes-amb answers RUN_DIR --out FILE``).

    res = physical_quantities(run, run.recording)   # engineering/quantities.py
    a = res.answers("posterior draws of the identification")
    a.quantities["bearing By: ks"].interval90
    a.save("runs/paper/answers.json"); EngineeringAnswers.load("runs/paper/answers.json")

The arrays behind the answers (eigenvalues per draw, sensitivities) stay on the
EngineeringResult; the file holds each quantity's median, 90 % interval and nominal value.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Self

from bayes_amb.errors import BayesAmbError
from bayes_amb.results.blocks import Block, block, omitted
from bayes_amb.results.files import read_block, write_result

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FORMAT = "bayes-amb-engineering/2"
FILE = "answers.json"


@block
class Answer(Block):
    """One derived quantity: its median over the draws, 90 % interval, nominal value
    (theta = 0), unit, group, the draws that gave a finite value, and whether it depends on
    the estimated parameters at all."""

    unit: str
    group: str
    value: float
    interval90: list[float]
    nominal: float
    n_valid: int
    estimated: bool = True


@block
class EngineeringAnswers(Block):
    """Modes, margins and sensitivities with their intervals (engineering/quantities.py)."""

    format: str = FORMAT
    model: str
    speeds_rpm: list[float]
    running_speed_rpm: float
    n_draws: int
    n_edge_points: int
    interval: str
    quantities: dict[str, Answer]
    notes: list[str]
    source: str | None = omitted()

    where = FILE

    def summary(self) -> str:
        """One line per quantity: median [90 % interval] unit, as the CLI prints it."""
        w = max((len(k) for k in self.quantities), default=0)
        return "\n".join(f"{k:<{w}} {q.value:>12.5g}  [{q.interval90[0]:.5g}, "
                         f"{q.interval90[1]:.5g}]  {q.unit}"
                         + ("" if q.estimated else "  (not estimated)")
                         for k, q in self.quantities.items())

    def _repr_html_(self) -> str:
        """The notebook view: one row per quantity (median, 90 % interval, nominal, unit) and
        the first group's figure."""
        from bayes_amb.results.html import result_html

        rows = [[k, f"{q.value:.5g}", f"[{q.interval90[0]:.5g}, {q.interval90[1]:.5g}]",
                 f"{q.nominal:.5g}", q.unit, "" if q.estimated else "not estimated"]
                for k, q in self.quantities.items()]
        return result_html(f"Engineering answers ({self.model} model, {self.n_draws} draws)",
                           f"running speed {self.running_speed_rpm:g} rpm; {self.interval}",
                           self.notes, [(["quantity", "median", "90 % interval", "nominal",
                                          "unit", ""], rows)], self.plot)

    def plot(self, group: str | None = None) -> Figure:
        """The quantities of one group (default: the first) as intervals about their
        medians, the nominal value marked (plots/engineering.py)."""
        from bayes_amb.plots.engineering import plot_answers

        groups = list(dict.fromkeys(q.group for q in self.quantities.values()))
        chosen = group or (groups[0] if groups else None)
        if chosen not in groups:
            raise BayesAmbError(f"plot group {group!r}: known groups {', '.join(groups)}")
        return plot_answers({k: q for k, q in self.quantities.items() if q.group == chosen},
                            chosen)

    def save(self, path: str | Path) -> Path:
        """Write the answers to ``path`` (a .json file, or a folder: its answers.json)."""
        p = Path(path)
        p = p / FILE if p.is_dir() else p
        write_result(p, self)
        return p

    @classmethod
    def load(cls, path: str | Path) -> Self:
        """The answers of a file, or of a run folder's answers.json."""
        p = Path(path)
        p = p / FILE if p.is_dir() else p
        return read_block(cls, p, FORMAT)
