"""The figures of ``virf bench latency``, typed: what ``--json`` prints and
what the Markdown page and the terminal tables are rendered from.

They are pydantic models because they live at the JSON edge both ways: a
run writes them (:meth:`Figures.public`) and a saved run is read back to
render the page again (:meth:`LatencyFigures.model_validate`).  A section a
run did not measure (the paper's method under ``--no-paper``, the cold
start under ``--cold-runs 0``) is left unset, and so out of the JSON.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, computed_field


class Figures(BaseModel):
    # Unknown keys are ignored: a saved run holds the derived figures
    # (fast_p50_ms...) too, and older runs may hold more.
    model_config = ConfigDict(frozen=True, extra="ignore")

    def public(self) -> dict[str, Any]:
        """The figures as JSON data: what was measured, nothing left unset."""
        return self.model_dump(exclude_unset=True)


class Machine(Figures):
    cpus: int | None
    python: str
    platform: str
    java: str


class Timings(Figures):
    """Per-plan milliseconds; NaN when no plan was timed."""

    p50_ms: float
    p95_ms: float
    mean_ms: float


class RoomTimings(Timings):
    room: str
    plans: int


class FastTimings(Timings):
    reasoner_calls: int
    fallbacks: int  # questions handed to the reference engine
    python_heap_peak_mb: float
    # Each plan's first timed run alone: it follows another plan's runs, so
    # nothing the engine keeps between runs of the same plan helps it.
    first_run_p50_ms: float | None = None
    first_run_ratio: float | None = None  # median of per-plan ratios b/c


class ReferenceTimings(Timings):
    plans: int


class Identical(Figures):
    compared: int
    identical: int


class Memory(Figures):
    process_rss_after_tbox_mb: float
    process_rss_peak_after_fast_mb: float
    process_rss_peak_after_reference_mb: float
    fast_python_heap_peak_mb: float


class ColdStartRow(Figures):
    engine: str
    runs: int
    verdict: str
    median_s: float
    min_s: float
    max_s: float


class ColdStart(Figures):
    example: str
    rows: tuple[ColdStartRow, ...]


class ScalingRow(Figures):
    """A synthetic case timed three ways; the scene-size rows also say the
    size asked for and, when the paper's method ran, its time."""

    objects: int
    steps: int
    status: str
    fast_ms: float
    reference_ms: float
    reference_2_workers_ms: float
    identical: bool
    requested_objects: int | None = None
    paper_ms: float | None = None
    paper_lower_bound: bool = False

    @property
    def size(self) -> int:
        """The scene size asked for (the scene holds the robot too)."""
        return self.objects if self.requested_objects is None else self.requested_objects


class ChainRow(Figures):
    objects: int
    steps: int
    status: str
    fast_ms: float


class HazardChainRow(Figures):
    objects: int
    status: str
    explained_facts: int
    fast_ms: float


class DeadlineRow(Figures):
    engine: str
    objects: int
    timeout_s: float
    status: str
    elapsed_ms: float


class TBoxRow(Figures):
    factor: int
    logical_axioms: int
    fast_ms: float
    reference_ms: float
    identical: bool


class PaperRow(Figures):
    """One plan of the paper's method: its time (None when a call failed),
    whether that is a lower bound, and each call's time or "> limit"."""

    plan: str
    ms: float | None
    lower_bound: bool
    calls: tuple[float | int | str | None, ...]


class PaperTimings(Timings):
    plans: int
    plans_lower_bound: int
    lower_bound: bool
    calls: int
    calls_over_limit: int
    call_limit_s: float | None
    per_call_p50_ms: float
    per_call_lower_bound: bool
    owlready2: str | None
    peak_rss_mb: float | None
    rows: tuple[PaperRow, ...]


class PaperComparison(Figures):
    """The paper's method against the fast engine on the same plans."""

    paper: PaperTimings
    ratio: float | None  # median of per-plan ratios a/c
    ratio_of_medians: float | None
    # A median of lower bounds is a lower bound of the median.
    ratio_lower_bound: bool
    paper_call_limit_s: float | None

    @computed_field  # type: ignore[prop-decorator]
    @property
    def paper_p50_ms(self) -> float:
        return self.paper.p50_ms


class LatencyFigures(Figures):
    machine: Machine
    plans: int
    repeats: int = 3
    cold_start: ColdStart | None = None
    rooms: tuple[RoomTimings, ...] = ()
    fast: FastTimings
    reference: ReferenceTimings
    identical_reports: Identical
    reference_ratio: float | None = None  # median of per-plan ratios b/c
    memory: Memory
    scene_scaling: tuple[ScalingRow, ...]
    length_scaling: tuple[ScalingRow, ...]
    chain_scaling: tuple[ChainRow, ...] = ()
    hazard_chains: tuple[HazardChainRow, ...] = ()
    deadline: tuple[DeadlineRow, ...] = ()
    tbox_scaling: tuple[TBoxRow, ...] = ()
    # The paper's method, when it ran (see PaperComparison).
    paper: PaperTimings | None = None
    paper_call_limit_s: float | None = None
    ratio: float | None = None
    ratio_of_medians: float | None = None
    ratio_lower_bound: bool = False

    # The headline figures, also at the top level of the JSON.
    @computed_field  # type: ignore[prop-decorator]
    @property
    def fast_p50_ms(self) -> float:
        return self.fast.p50_ms

    @computed_field  # type: ignore[prop-decorator]
    @property
    def fast_p95_ms(self) -> float:
        return self.fast.p95_ms

    @computed_field  # type: ignore[prop-decorator]
    @property
    def reference_p50_ms(self) -> float:
        return self.reference.p50_ms

    @computed_field  # type: ignore[prop-decorator]
    @property
    def reference_p95_ms(self) -> float:
        return self.reference.p95_ms

    @computed_field  # type: ignore[prop-decorator]
    @property
    def paper_p50_ms(self) -> float | None:
        return None if self.paper is None else self.paper.p50_ms
