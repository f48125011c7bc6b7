"""A stand-in child for ``Supervisor``'s stop tests (``test_stopping.py``): ``python -m
tests.transport._stopper NAME FILE`` prints ``ready``, and on SIGTERM writes ``NAME term <time>`` to FILE,
takes 0.3 s (a world ending its run), writes ``NAME exit <time>`` and exits 0; with a third argument
``starting`` it never says it is ready (a child still loading its kernels)."""

from __future__ import annotations

import signal
import sys
import time


def main() -> None:
    name, path = sys.argv[1], sys.argv[2]

    def on_term(*_: object) -> None:
        with open(path, "a") as fh:
            fh.write(f"{name} term {time.time():.6f}\n")
        time.sleep(0.3)
        with open(path, "a") as fh:
            fh.write(f"{name} exit {time.time():.6f}\n")
        sys.exit(0)

    signal.signal(signal.SIGTERM, on_term)
    if sys.argv[3:] != ["starting"]:
        print("ready", flush=True)
    while True:
        time.sleep(0.05)


if __name__ == "__main__":
    main()
