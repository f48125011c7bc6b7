"""``swarm bench checkpoint``: what the world's checkpoint costs per tick (issue 7: a world restarted).

The world process writes its complete state every tick before it publishes the tick's samples
(:mod:`swarm.transport.checkpoint`). This bench steps a world of 1, 4 and 16 pairs without Zenoh, as its run
loop does (step, encode the samples, checkpoint), and times the checkpoint alone: the snapshot, the
pickle, the CRCs and the write of a slot in place (with the recent ticks' samples), into a directory in
memory (``/dev/shm``, where ``swarm launch`` puts it) and one on the default temporary file system (a disk,
here ext4), for comparison with the lockstep tick (~1.6 ms for one pair, ``BENCHMARKS.md``, "Transport").

The landing swarm (``landing-swarm``, four UAVs) has two: its world's (:mod:`swarm.world.landing`: the
world's snapshot, the tick's encoded samples) and each agent's (:mod:`agents.landing`: the agent's snapshot,
written after its decision), both every tick. The bench flies the four UAVs in process as the processes do
(world step, the tick's samples encoded, agent tick) and times each write alone, beside the tick's own
compute (the world's step and the four agents' ticks, without Zenoh).
"""

from __future__ import annotations

import shutil
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

FULL = {"pairs": (1, 4, 16), "ticks": 2000, "landing_ticks": 2000}  # (a landing-swarm run: 1786 ticks)
QUICK = {"pairs": (1, 4), "ticks": 300, "landing_ticks": 300}


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


def _landing(ticks: int, base: str | None) -> dict:
    """The landing world's and one agent's checkpoint per tick (module docstring)."""
    from swarm.landing_scenario import load_landing
    from swarm.step.landing import LandingAgent, LandingWorld
    from swarm.transport import wire
    from swarm.transport.checkpoint import CheckpointFile, checkpoint_path
    from swarm.transport.keys import Keys

    sc = load_landing("landing-swarm")
    keys = Keys("bench")
    world = LandingWorld(sc, 0)
    agents = {u.id: LandingAgent(sc, 0, u.index, sc.policy) for u in sc.uavs()}
    first = sc.uavs()[0].id
    directory = tempfile.mkdtemp(prefix="swarm-bench-ckpt-", dir=base)
    try:
        w_file = CheckpointFile(checkpoint_path(directory))
        a_file = CheckpointFile(checkpoint_path(directory, f"agent-{first}.ckpt"))
        w_t, a_t, tick_t, w_bytes, a_bytes = [], [], [], 0, 0
        for k in range(1, ticks + 1):
            t0 = time.perf_counter()
            inputs = world.step(k)
            if not inputs:
                break
            tick_wire = wire.landing_world_tick(keys, world, k, inputs, 0)
            t1 = time.perf_counter()
            w_bytes = w_file.write({"tick": k, "world": world.snapshot(), "wire": tick_wire})
            t2 = time.perf_counter()
            for uid, inp in inputs.items():
                cmd = agents[uid].tick(inp)
                world.hold(uid, cmd)
                if uid == first:
                    t3 = time.perf_counter()
                    snap = agents[uid].snapshot()
                    a_bytes = a_file.write({"k": k + 1, "agent": snap["state"]}, snap["records"])
                    t4 = time.perf_counter()
            t5 = time.perf_counter()
            w_t.append(t2 - t1)
            if first in inputs:
                a_t.append(t4 - t3)
            tick_t.append((t5 - t0) - (t2 - t1) - (t4 - t3 if first in inputs else 0.0))
        w_file.close()
        a_file.close()

        def stats(xs: list[float]) -> dict:
            us = 1e6 * np.array(xs)
            return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
                    "mean_us": float(us.mean())}  # fmt: skip

        return {"uavs": len(agents), "ticks": len(tick_t), "world": {"bytes": w_bytes, **stats(w_t)},
                "agent": {"bytes": a_bytes, **stats(a_t)}, "tick": stats(tick_t)}  # fmt: skip
    finally:
        shutil.rmtree(directory, ignore_errors=True)


def run(cfg: dict) -> dict:
    """Checkpoint cost per tick by file system and number of pairs; the landing swarm's beside."""
    results = {name: [_one(p, cfg["ticks"], base) for p in cfg["pairs"]] for name, base in _dirs().items()}
    landing = {name: _landing(cfg["landing_ticks"], base) for name, base in _dirs().items()}
    return {"ticks": cfg["ticks"], "results": results, "landing": landing}


def format_report(record: dict) -> str:
    lines = [f"world checkpoint per tick ({record['ticks']} ticks; snapshot + pickle + CRC + write + rename)"]
    for name, rows in record["results"].items():
        lines.append(f"  {name}:")
        for r in rows:
            lines.append(f"    {r['pairs']:>2} pairs: {r['bytes']:>6} bytes, median {r['median_us']:7.1f} "
                         f"us, p99 {r['p99_us']:7.1f} us, mean {r['mean_us']:7.1f} us")  # fmt: skip
    for name, r in record.get("landing", {}).items():
        lines.append(
            f"  landing-swarm ({r['uavs']} UAVs, {r['ticks']} ticks), {name}: median / p99 / mean [us]"
        )
        for what in ("world", "agent"):
            c = r[what]
            lines.append(f"    {what} checkpoint: {c['bytes']:>6} bytes, {c['median_us']:7.1f} / "
                         f"{c['p99_us']:7.1f} / {c['mean_us']:7.1f}")  # fmt: skip
        t = r["tick"]
        lines.append(f"    the tick's compute (world step + {r['uavs']} agents): {t['median_us']:7.1f} / "
                     f"{t['p99_us']:7.1f} / {t['mean_us']:7.1f}")  # fmt: skip
    return "\n".join(lines)
