"""Recorded sensor logs: the CSV format (``docs/logs.md``), a synthetic log maker, calibration and replay."""
