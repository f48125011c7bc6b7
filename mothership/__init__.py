"""The mothership process (``python -m mothership``): anchor registry and simulated UWB radio network."""

import swarm  # noqa: F401  (first: it pins numpy's BLAS kernels, swarm._pin_blas_kernels)
