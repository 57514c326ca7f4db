"""How a fleet's flight ended: each companion's exit code and JSON summary."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

__all__ = ["VehicleResult", "FleetResult", "last_json_line"]


@dataclass(frozen=True)
class VehicleResult:
    """How one vehicle's companion ended: exit code and its JSON summary's outcome and legs."""

    sysid: int
    mission: str
    exit_code: int | None
    outcome: str
    legs_reached: int | None
    legs_planned: int | None
    summary: dict | None

    @property
    def completed(self) -> bool:
        return self.exit_code == 0 and self.outcome == "completed"

    def as_dict(self) -> dict:
        return {
            "sysid": self.sysid,
            "mission": self.mission,
            "exit_code": self.exit_code,
            "outcome": self.outcome,
            "legs_reached": self.legs_reached,
            "legs_planned": self.legs_planned,
            "completed": self.completed,
        }


@dataclass(frozen=True)
class FleetResult:
    """The fleet's end: one ``VehicleResult`` per vehicle; ``completed`` iff every mission was."""

    vehicles: tuple[VehicleResult, ...]
    wall_s: float

    @property
    def completed(self) -> bool:
        return bool(self.vehicles) and all(v.completed for v in self.vehicles)

    def as_dict(self) -> dict:
        return {
            "completed": self.completed,
            "wall_s": round(self.wall_s, 1),
            "vehicles": [v.as_dict() for v in self.vehicles],
        }

    def table(self) -> str:
        """One line per vehicle, for people."""
        lines = [f"{'sysid':>5}  {'exit':>4}  {'legs':>5}  outcome"]
        for v in self.vehicles:
            legs = "-" if v.legs_planned is None else f"{v.legs_reached}/{v.legs_planned}"
            code = "-" if v.exit_code is None else str(v.exit_code)
            lines.append(f"{v.sysid:>5}  {code:>4}  {legs:>5}  {v.outcome}")
        lines.append(
            f"{'all missions completed' if self.completed else 'NOT all missions completed'} ({self.wall_s:.0f} s)"
        )
        return "\n".join(lines)


def last_json_line(path: Path) -> dict | None:
    """The last line of ``path`` that is a JSON object (``companion run``'s summary), or None."""
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return None
    for line in reversed(text.splitlines()):
        if line.startswith("{"):
            try:
                value = json.loads(line)
            except json.JSONDecodeError:
                return None
            return value if isinstance(value, dict) else None
    return None
