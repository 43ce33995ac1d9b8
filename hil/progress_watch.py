"""Stops a lockstep run whose simulated time advances too slowly (issue 31, point 2).

Lockstep runs as fast as the two processes can, so a run is never "late"; but a combination of
in-range settings (the largest planner iteration budget with the shortest planning period) or a
machine that starves the loop can make it crawl until the wall timeout. :class:`ProgressWatch`
looks at consecutive windows of ``window_s`` wall seconds and reports, in one line, a window in which
simulated time advanced less than ``min_rate`` times the wall time.
"""

from __future__ import annotations

STALL_WINDOW_S = 60.0   # s of wall time per check (longer than a lockstep planning cycle may take)
MIN_RATE = 0.02         # simulated s per wall s below which a lockstep run is stopped (1/50 of real time)


class ProgressWatch:
    """Feed it (wall time, simulated time) pairs; :meth:`check` gives the reason to stop, or None."""

    def __init__(self, window_s: float = STALL_WINDOW_S, min_rate: float = MIN_RATE) -> None:
        if not (window_s > 0 and min_rate > 0):
            raise ValueError(f"progress window {window_s} s and rate {min_rate} must be > 0")
        self.window_s, self.min_rate = window_s, min_rate
        self._mark: tuple[float, float] | None = None

    def check(self, wall: float, sim: float) -> str | None:
        """``wall`` (s, monotonic) and the newest simulated time (s)."""
        if self._mark is None:
            self._mark = (wall, sim)
            return None
        wall0, sim0 = self._mark
        if wall - wall0 < self.window_s:
            return None
        advanced = sim - sim0
        if advanced < self.min_rate * (wall - wall0):
            return (f"simulated time advanced {advanced:.2f} s in {wall - wall0:.0f} s of wall time "
                    f"(less than 1/{1 / self.min_rate:.0f} of real time): stopped; lower "
                    f"autopilot.lockstep_iterations, raise autopilot.planning_period or sim.dt")
        self._mark = (wall, sim)
        return None
