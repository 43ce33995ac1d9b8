"""What the tests share that is not a test: planner doubles, a scripted ground station, the CAN checks
run inside User-Mode Linux, sample summaries. Imported as ``support.NAME`` (pytest puts tests/ on
sys.path, as it does for tests/conftest.py)."""
