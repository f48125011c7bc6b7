"""The agent process (``python -m agents``): one vehicle's estimator, switcher, guidance and control."""

import swarm  # noqa: F401  (first: it pins numpy's BLAS kernels, swarm._pin_blas_kernels)
