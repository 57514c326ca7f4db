"""Path planning: GART and M-GART (paper sections 3.1 and 3.3), cost (eq. 3), shortcutting.

``gart(world, start, goal, *, rng, ...) -> PlanResult`` and
``mgart(world, start, goal, k, *, rng, ...) -> list[PlanResult]``; see DESIGN section 4.
"""

from companion.planning.cost import path_cost, path_length_m
from companion.planning.gart import gart
from companion.planning.mgart import hausdorff_m, mgart
from companion.planning.result import PlanResult, Tree
from companion.planning.settings import CostWeights, GartSettings, MgartSettings, SimplifySettings
from companion.planning.simplify import shortcut_path

__all__ = [
    "gart",
    "mgart",
    "PlanResult",
    "Tree",
    "GartSettings",
    "MgartSettings",
    "CostWeights",
    "SimplifySettings",
    "path_cost",
    "path_length_m",
    "shortcut_path",
    "hausdorff_m",
]
