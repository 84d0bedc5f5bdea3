"""Checks of recorded runs: expectations files and re-run comparison (CLI and pytest)."""
