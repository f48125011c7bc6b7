"""The agent process (``python -m agents``): one vehicle's estimator, switcher, guidance and control."""
