"""A process that answers the stacks signal (swarm/stacks.py), sleeps in a function this test can find in its
stack, and prints ``up`` once ``--quiet-s`` seconds have passed (0: at once; for the supervisor's tests)."""

import sys
import time

from swarm.stacks import enable_stack_dumps


def waiting_in_the_waiter() -> None:
    time.sleep(600)


if __name__ == "__main__":
    quiet_s = float(sys.argv[sys.argv.index("--quiet-s") + 1]) if "--quiet-s" in sys.argv else 0.0
    time.sleep(quiet_s)
    enable_stack_dumps()
    print("up", flush=True)
    waiting_in_the_waiter()
