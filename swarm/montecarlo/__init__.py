"""Monte Carlo campaigns of the docking scenario (paper section V-C: Table II, Fig. 5, Fig. 6).

* :mod:`swarm.kinds.dispersions`: the per-run dispersions a scenario declares (``[dispersions]``),
  drawn from the run's own seed inside :class:`swarm.sim.docking.DockingSim`, so ``swarm sim --seed S``
  with the campaign's saved scenario re-runs any run exactly;
* :mod:`swarm.montecarlo.campaign`: paired runs of several policies on any ``concurrent.futures``
  executor, saved run by run (resumable);
* :mod:`swarm.montecarlo.stats`: Table II statistics with t intervals and the paired test;
* :mod:`swarm.montecarlo.report`: ``report.md`` and the figures.

This package's ``__init__`` imports nothing: the simulator imports :mod:`.dispersions` at start-up.
"""
