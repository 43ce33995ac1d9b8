"""The LLVM optimisation level of the vessel computer's numba kernels, set before they compile.

``NUMBA_OPT`` (numba's default 3) is 1 in the processes that compile or run the planner's and
the vessel computer's kernels: ``hil autopilot`` (the vessel computer), ``hil plan`` and the
``planner`` and ``vessel-computer`` groups of ``hil.warm_up``, unless the user's environment sets
it (any value numba accepts, e.g. ``NUMBA_OPT=3 hil run``). The simulator's processes keep
numba's default: level 1 made its frame ~1.2x slower for no compile time worth having (its
kernels compile in ~2.5 s). Measured on the project's 2-core machine (docs/performance.md, "The
first run compiles"): level 1 cuts ~2 s of CPU from the planner's cold compile and ~3.5 s from
the vessel computer's; the planner runs as fast (iterations per CPU second 0.97 of level 3's,
within the spread) with bit-identical trees, the filter's step within the spread too. Without
fast-math flags LLVM keeps IEEE results at every level, so machine code cached at one level
gives the same numbers as another (numba's cache does not key on the level). The planner package
itself sets nothing (a pure library).
"""

from __future__ import annotations

import os

NUMBA_OPT = "1"
# The hil.warm_up groups compiled at NUMBA_OPT (the simulator's group keeps numba's default).
LOW_OPT_GROUPS = ("planner", "vessel-computer")


def apply() -> None:
    """Set ``NUMBA_OPT`` for this process and the processes it starts, unless the user set it.
    Call before the process compiles a kernel (numba reads the level again at each compile)."""
    os.environ.setdefault("NUMBA_OPT", NUMBA_OPT)
