"""The simulated world as a process (``python -m swarm.world``): truth dynamics and on-board sensors of
every vehicle, published over Zenoh (:mod:`swarm.world.process`)."""
