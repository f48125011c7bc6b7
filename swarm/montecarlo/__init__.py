"""Monte Carlo campaigns of every mission (paper section V-C: Table II, Figs. 5-6; section VI-B: Figs. 9-10).

* :mod:`swarm.kinds.dispersions`: the per-run dispersions a scenario declares (``[dispersions]``),
  drawn from the run's own seed inside :class:`swarm.sim.docking.DockingSim`, so ``swarm sim --seed S``
  with the campaign's saved scenario re-runs any run exactly;
* :mod:`swarm.montecarlo.campaign`: paired runs of several policies on any ``concurrent.futures``
  executor, saved run by run (resumable), for any mission's :class:`~swarm.montecarlo.campaign.
  CampaignMission` (the docking's in :mod:`.run` and :mod:`.report`, the landing's in :mod:`.landing`);
* :mod:`swarm.montecarlo.stats`: Table II statistics with t intervals and the paired test;
* :mod:`swarm.montecarlo.report`: ``report.md`` and the figures.

This package's ``__init__`` imports nothing: the simulator imports :mod:`.dispersions` at start-up.
"""
