"""Running estimate of a decision step's wall-clock time (a value of the decision state)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["RunningEstimate"]


@dataclass(frozen=True)
class RunningEstimate:
    """Mean and mean absolute deviation of a step's measured wall-clock time (s).

    Attributes
    ----------
    mean_s : float
        The first guess until a sample was measured, then the running mean.
    dev_s : float
        Running mean absolute deviation (s).
    samples : int
        Measurements taken in.
    """

    mean_s: float
    dev_s: float = 0.0
    samples: int = 0

    def updated(self, measured_s: float, gain: float) -> RunningEstimate:
        """This estimate with one more measurement (the first replaces the guess)."""
        if self.samples == 0:
            return RunningEstimate(measured_s, 0.25 * measured_s, 1)
        err = measured_s - self.mean_s
        return RunningEstimate(self.mean_s + gain * err, self.dev_s + gain * (abs(err) - self.dev_s), self.samples + 1)

    @property
    def high_s(self) -> float:
        """Mean + 3 mean absolute deviations (s): a pessimistic duration."""
        return self.mean_s + 3.0 * self.dev_s
