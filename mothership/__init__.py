"""The mothership process (``python -m mothership``): anchor registry and simulated UWB radio network."""
