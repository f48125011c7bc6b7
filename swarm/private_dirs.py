"""Private temporary directories of a process that must not outlive it, even when it is SIGKILLed.

``swarm launch`` keeps the world's checkpoints in memory (``/dev/shm``) and, with ``--secure``, its keys in a
temporary directory; it removes both when it exits, but a SIGKILLed launcher runs no clean-up, and tmpfs
holds what it leaves until the machine reboots. So each such directory carries the pid of its owner
(``<prefix><pid>-XXXXXXXX``), and making a new one first removes those whose owner is gone.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    return True


def private_dir(prefix: str, base: str | None = None) -> Path:
    """A new directory ``<base>/<prefix><pid>-XXXXXXXX`` of mode 0700 (``tempfile.mkdtemp``; ``base=None``:
    the system's temporary directory), after removing the directories of this prefix there whose owner
    process no longer exists."""
    root = Path(base) if base is not None else Path(tempfile.gettempdir())
    for old in root.glob(f"{prefix}*-*"):
        pid = old.name[len(prefix) :].split("-", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            shutil.rmtree(old, ignore_errors=True)
    return Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-", dir=base))
