"""The Viser web dashboard process (docs/usage.md, "Dashboard"): ``python -m dashboard``, ``swarm dashboard``.

It subscribes to a swarm over Zenoh and sends run controls, or plays an MCAP recording (``--open``); it
never runs estimator or guidance code. Modules: :mod:`dashboard.mapping` (pure: messages to scene names,
poses, colours, geometry; the one ``xyzw -> wxyz`` conversion), :mod:`dashboard.panels` (pure: GUI text and
plot data), :mod:`dashboard.state` (thread-safe store, bounded trails and series, frame pacing),
:mod:`dashboard.link` (Zenoh side), :mod:`dashboard.playback` (a recording instead), :mod:`dashboard.app`
(Viser scene, GUI, render thread) and :mod:`dashboard.cli` (command line).
"""

import swarm  # noqa: F401  (first: it pins numpy's BLAS kernels, swarm._pin_blas_kernels)
