"""``python -m agents SCENARIO --id ID [flags]``: one vehicle's agent process (same as ``swarm agent``)."""

from __future__ import annotations

import sys

from agents.cli import main

if __name__ == "__main__":
    sys.exit(main())
