"""Benchmarks behind ``swarm bench`` (BENCHMARKS.md): one module per bench, each returning a
JSON-ready dict (section 8 names) and a printable report. Ratios are measured in one process run,
because the machines here are shared and noisy; absolute numbers are only indicative."""
