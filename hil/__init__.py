"""Command line and orchestration of the USV HIL stack (`hil ...`)."""
