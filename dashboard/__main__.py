"""``python -m dashboard SCENARIO --port 8080 --connect tcp/127.0.0.1:7447``: see :mod:`dashboard.cli`."""

from __future__ import annotations

import sys

from dashboard.cli import main

sys.exit(main())
