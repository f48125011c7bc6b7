"""Offline analyses of a scenario (no simulation): :mod:`.anchors` is the paper's section V-D study."""
