"""``python -m mothership SCENARIO [flags]``: the mothership process (same as ``swarm mothership``)."""

from __future__ import annotations

import sys

from mothership.cli import main

if __name__ == "__main__":
    sys.exit(main())
