"""``swarm bench checkpoint``: what the world's checkpoint costs per tick (issue 7: a world restarted).

The world process writes its complete state every tick before it publishes the tick's samples
(:mod:`swarm.world.checkpoint`). This bench steps a world of 1, 4 and 16 pairs without Zenoh, as its run
loop does (step, encode the samples, checkpoint), and times the checkpoint alone: the snapshot, the
pickle, the CRCs and the write of a slot in place (with the recent ticks' samples), into a directory in
memory (``/dev/shm``, where ``swarm launch`` puts it) and one on the default temporary file system (a disk,
here ext4), for comparison with the lockstep tick (~1.6 ms for one pair, ``BENCHMARKS.md``, "Transport").
"""

from __future__ import annotations

import shutil
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

FULL = {"pairs": (1, 4, 16), "ticks": 2000}
QUICK = {"pairs": (1, 4), "ticks": 300}


def _dirs() -> dict[str, str | None]:
    shm = Path("/dev/shm")
    out: dict[str, str | None] = {"tmpfs": str(shm)} if shm.is_dir() else {}
    out[f"default ({tempfile.gettempdir()})"] = None
    return out


def _one(pairs: int, ticks: int, base: str | None) -> dict:
    from swarm.scenario import load_scenario
    from swarm.transport.keys import Keys
    from swarm.transport.process import ClockSpec
    from swarm.world.process import WorldProcess

    sc = load_scenario("docking").with_pairs(pairs)
    directory = tempfile.mkdtemp(prefix="swarm-bench-ckpt-", dir=base)
    try:
        stop = threading.Event()
        wp = WorldProcess(sc, 0, None, Keys("bench"), ClockSpec(), stop, checkpoint_dir=directory)
        times = []
        for _ in range(ticks):
            frames = wp.world.step()
            wp._new_tick(wp.world.k, frames)  # with the earlier ticks' samples, as a run keeps them
            t0 = time.perf_counter()
            wp._checkpoint()
            times.append(time.perf_counter() - t0)
        us = 1e6 * np.array(times)
        return {"pairs": pairs, "bytes": wp.ckpt_bytes, "median_us": float(np.median(us)),
                "p99_us": float(np.percentile(us, 99)), "mean_us": float(us.mean())}  # fmt: skip
    finally:
        shutil.rmtree(directory, ignore_errors=True)


def run(cfg: dict) -> dict:
    """Checkpoint cost per tick by file system and number of pairs."""
    results = {name: [_one(p, cfg["ticks"], base) for p in cfg["pairs"]] for name, base in _dirs().items()}
    return {"ticks": cfg["ticks"], "results": results}


def format_report(record: dict) -> str:
    lines = [f"world checkpoint per tick ({record['ticks']} ticks; snapshot + pickle + CRC + write + rename)"]
    for name, rows in record["results"].items():
        lines.append(f"  {name}:")
        for r in rows:
            lines.append(f"    {r['pairs']:>2} pairs: {r['bytes']:>6} bytes, median {r['median_us']:7.1f} "
                         f"us, p99 {r['p99_us']:7.1f} us, mean {r['mean_us']:7.1f} us")  # fmt: skip
    return "\n".join(lines)
