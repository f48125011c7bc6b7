"""``python -m swarm.world SCENARIO [flags]``: the world process (same as ``swarm world``)."""

from __future__ import annotations

import sys

from swarm.world.cli import main

if __name__ == "__main__":
    sys.exit(main())
