"""The numba settings of hil's processes, set before anything imports numba.

``NUMBA_OPT`` (LLVM's optimisation level for numba's machine code, numba's default 3) is 1 in
every process `hil` starts, unless the user's environment sets it (any value numba accepts,
e.g. ``NUMBA_OPT=3 hil run``). Measured on the project's 2-core machine (docs/performance.md,
"The first run compiles"): level 1 cuts LLVM's share of a cold compile by ~2 s of CPU in the
planner's kernels and the planner runs as fast (iterations per CPU second 0.97 of level 3's,
within the spread), with bit-identical trees: without fast-math flags LLVM keeps IEEE results at
every level. The planner package itself sets nothing (a pure library); the child processes of a
run inherit the variable.
"""

from __future__ import annotations

import os

NUMBA_OPT = "1"


def apply() -> None:
    """Set hil's numba defaults in this process's environment (inherited by its children); a
    variable the user set is kept. Call before numba is imported."""
    os.environ.setdefault("NUMBA_OPT", NUMBA_OPT)
