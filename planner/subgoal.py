"""Section 3.1: choosing the local subgoal on the global reference path.

The perceptual domain is the disc of ``radius`` about the vessel's position. Rules (paper's
numbering):

1. the global goal is in the domain -> the goal;
2. q_j, the reference waypoint nearest the vessel, is the last waypoint (no q_{j+1} exists)
   but lies outside the domain -> q_j (rule 2 defines q_j; this is the case where only q_j
   itself is left to choose);
3. q_j in the domain -> the first q_m after it with q_m in and q_{m+1} out;
4. q_j out, q_{j+1} in -> the outermost (last consecutive) in-domain waypoint from q_{j+1};
5. q_j and q_{j+1} out -> q_j (the vessel has drifted off the reference path).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class Subgoal:
    index: int
    point: tuple[float, float]
    rule: int


def select_subgoal(reference_path: np.ndarray, position: npt.ArrayLike, radius: float, goal_index: int | None = None,
                   start: npt.ArrayLike | None = None) -> Subgoal:
    """The subgoal for a vessel at ``position`` (the perceptual domain's centre) with perceptual
    radius ``radius`` (metres). ``start`` is the local planning start point (default
    ``position``; the root of the next local tree may lie ahead of the vessel), q_j is the
    reference waypoint nearest to it. ``goal_index`` is the global goal's index on the path
    (default: its last waypoint)."""
    path = np.asarray(reference_path, dtype=np.float64)
    if path.ndim != 2 or path.shape[1] != 2 or len(path) == 0:
        raise ValueError("reference_path must be an (M, 2) array with M >= 1")
    last = len(path) - 1 if goal_index is None else int(goal_index)
    if not 0 <= last < len(path):
        raise ValueError("goal_index outside the reference path")
    pos = np.asarray(position, dtype=np.float64)
    dist = np.hypot(path[: last + 1, 0] - pos[0], path[: last + 1, 1] - pos[1])
    inside = dist <= radius

    def pick(i: int, rule: int) -> Subgoal:
        return Subgoal(int(i), (float(path[i, 0]), float(path[i, 1])), rule)

    if inside[last]:
        return pick(last, 1)
    st = pos if start is None else np.asarray(start, dtype=np.float64)
    j = int(np.argmin(np.hypot(path[: last + 1, 0] - st[0], path[: last + 1, 1] - st[1])))
    if j == last:
        return pick(j, 2)
    if inside[j]:
        m = j
        while m + 1 <= last and inside[m + 1]:
            m += 1
        return pick(m, 3)
    if inside[j + 1]:
        m = j + 1
        while m + 1 <= last and inside[m + 1]:
            m += 1
        return pick(m, 4)
    return pick(j, 5)
