"""Records of the refinement's steps: what each did, and the seconds their two halves took."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Iteration", "StepClock"]


@dataclass
class Iteration:
    """What one refinement step did."""

    #: Hop radius of the step; 0 for a global repair step.
    k: int
    witness_fraction: float
    changed: int
    seconds: float
    #: The 0-based pass the step belongs to (the polish: the last pass that ran).
    n_pass: int = 0
    #: The final polishing step (see ``polish_k``), not a step of a pass.
    polish: bool = False
    #: Of ``seconds``, those spent building the overlap cost and solving its assignment (0 for
    #: a repair step and for the polish, which is not one to one).
    cost_seconds: float = 0.0
    assign_seconds: float = 0.0
    #: A k-hop step that took the result of an earlier step with the same inputs instead of
    #: solving (see :class:`~hope_rs.pipeline.refine_steps.KHop`).
    reused: bool = False


@dataclass
class StepClock:
    """Seconds the HOPE steps of a stage spent in their two halves, summed over its steps:
    building the overlap cost (parallel) and solving the assignment (sequential)."""

    cost: float = 0.0
    assign: float = 0.0
    steps: int = 0

    def add(self, cost: float, assign: float) -> None:
        self.cost += cost
        self.assign += assign
        self.steps += 1

    def record(self, timings: dict, stage: str) -> None:
        """Adds ``stage + ".cost"`` and ``stage + ".assign"`` to ``timings`` when a step ran."""
        if self.steps:
            timings[f"{stage}.cost"] = self.cost
            timings[f"{stage}.assign"] = self.assign
