"""swarm.private_dirs: a private directory names its owner, and the ones of dead owners are removed."""

from __future__ import annotations

import os
import subprocess
import sys

from swarm.private_dirs import private_dir


def test_a_new_private_dir_removes_those_of_dead_owners_only(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # reaped: its pid names no process (the kernel does not reuse it this soon)
    orphan = tmp_path / f"swarm-world-{dead.pid}-abcdefgh"
    (orphan / "run-0").mkdir(parents=True)
    (orphan / "run-0" / "world.ckpt").write_bytes(b"x")
    live = tmp_path / f"swarm-world-{os.getppid()}-abcdefgh"  # the pytest process's parent is alive
    live.mkdir()
    other = tmp_path / "swarm-world-notapid-abcdefgh"  # not of this scheme: left alone
    other.mkdir()
    new = private_dir("swarm-world-", str(tmp_path))
    assert not orphan.exists()
    assert live.is_dir() and other.is_dir()
    assert new.is_dir() and new.name.startswith(f"swarm-world-{os.getpid()}-")
    assert (new.stat().st_mode & 0o777) == 0o700
    again = private_dir("swarm-world-", str(tmp_path))  # this process's own directory stays
    assert new.is_dir() and again != new
