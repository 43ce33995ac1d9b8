import os
import sys

from hil.cli import main

code = main()
if sys.argv[1:2] in (["sim"], ["autopilot"]):
    # The processes of a HIL run: their summary is printed and every socket, bus and file closed
    # by now. The interpreter's teardown (0.3-0.5 s with numba, llvmlite and scipy loaded) is
    # skipped, since `hil run` waits for these processes to end before it goes on.
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)
sys.exit(code)
