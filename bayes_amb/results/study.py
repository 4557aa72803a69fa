"""The result of a study: :class:`Study`, the typed content of a study folder's study.json.

    rows = run_study(spec, "runs/noise"); s = finalise(spec, rows, "runs/noise")
    s = Study.load("runs/noise")                 # or a finished folder, later
    s.conclusions, s.sbc, s.rows[0]["k_By_mean"]
    s.plot("sbc_coverage")

``study.json`` (format ``bayes-amb-study/1``) holds the study's definition, its cells and
seeds, and once finished its conclusions, SBC statistics or benchmark table. The rows of
``results.jsonl`` (one per replicate, keys of the study's own making) come with a loaded
study as ``rows``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

from bayes_amb.errors import BayesAmbError
from bayes_amb.results.blocks import Block, block, omitted, runtime
from bayes_amb.results.files import read_block, read_rows, write_result

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FORMAT = "bayes-amb-study/1"
FILE = "study.json"


@block
class Study(Block):
    """A study folder's manifest: definition, cells, seeds; after finalise its
    conclusions, SBC statistics (inference studies) or benchmark table (diagnose)."""

    format: str = FORMAT
    package_version: str
    study: dict[str, Any]
    source: str | None = None
    cells: list[dict[str, Any]]
    seeds: dict[str, Any]
    n_rows: int | None = omitted()
    failures: int | None = omitted()
    conclusions: list[str] | None = omitted()
    sbc: dict[str, Any] | None = omitted()
    benchmark: dict[str, Any] | None = omitted()
    wall_s_total: float | None = omitted()

    rows: list[dict[str, Any]] | None = runtime()

    where = FILE

    @property
    def spec(self) -> dict[str, Any]:
        """The study file's own table (name, description, seed, ...)."""
        inner = self.study.get("study")
        return inner if isinstance(inner, dict) else self.study

    @property
    def name(self) -> str:
        return str(self.spec.get("name", ""))

    @property
    def description(self) -> str:
        return str(self.spec.get("description", ""))

    @property
    def seed(self) -> int | None:
        seed = self.spec.get("seed")
        return seed if isinstance(seed, int) else None

    @property
    def finished(self) -> bool:
        return self.conclusions is not None

    def summary(self) -> str:
        """The study's name, size and conclusions."""
        head = (f"study '{self.name}': {self.n_rows} replicates ({self.failures} failed)"
                if self.finished else f"study '{self.name}': not finished")
        return "\n".join([head, *(f"  - {c}" for c in self.conclusions or [])])

    def _repr_html_(self) -> str:
        """The notebook view: name, size and conclusions, the cells, and the SBC coverage
        or benchmark figure when the study has one."""
        from bayes_amb.results.html import result_html

        rows = [[i + 1, ", ".join(f"{k}={v}" for k, v in c.items()
                                  if not isinstance(v, (dict, list)))]
                for i, c in enumerate(self.cells[:20])]
        kind = "sbc_coverage" if self.sbc else "benchmark" if self.benchmark else None
        head = self.summary().splitlines()
        return result_html(f"Study '{self.name}'", head[0], [self.description, *head[1:]],
                           [(["cell", "settings"], rows)],
                           (lambda: self.plot(kind)) if kind else None)

    def plot(self, kind: str = "sbc_coverage") -> Figure:
        """A figure of plots/studies.py: sbc_ranks or sbc_coverage (studies that draw from
        the prior), or benchmark (the concealed-effect benchmark)."""
        from bayes_amb.plots import discrepancy, studies

        if kind in ("sbc_ranks", "sbc_coverage") and self.sbc:
            return (studies.plot_sbc_ranks if kind == "sbc_ranks"
                    else studies.plot_sbc_coverage)(self.sbc)
        if kind == "benchmark" and self.benchmark:
            return discrepancy.plot_benchmark(self.benchmark)
        raise BayesAmbError(f"plot kind {kind!r}: this study has "
                            + ("SBC statistics (sbc_ranks, sbc_coverage)" if self.sbc else
                               "a benchmark table (benchmark)" if self.benchmark else
                               "no figure of its own (not finished, or no SBC)"))

    def save(self, out_dir: str | Path) -> Path:
        """Write OUT/study.json atomically (the rows stay in results.jsonl)."""
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        write_result(d / FILE, self)
        return d

    @classmethod
    def load(cls, out_dir: str | Path) -> Self:
        """The study a folder holds (study.json, and the rows of results.jsonl)."""
        import dataclasses

        d = Path(out_dir)
        out = read_block(cls, d / FILE, FORMAT)
        return dataclasses.replace(out, rows=read_rows(d / "results.jsonl"))

    @staticmethod
    def upgrade(data: dict[str, Any]) -> dict[str, Any]:
        """An older study.json's single conclusion (a string) as a list of one."""
        if isinstance(data.get("conclusions"), str):
            data["conclusions"] = [data["conclusions"]]
        return data
