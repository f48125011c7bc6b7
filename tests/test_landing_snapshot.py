"""The landing world's and agent's snapshots (what a restarted landing world or agent resumes from): a run
restored mid-flight from them goes on bit for bit as the uninterrupted one, the snapshots stay small, and
one of another world is refused."""

from __future__ import annotations

import pickle
import zlib

import numpy as np
import pytest

from swarm.landing_scenario import load_landing
from swarm.step.landing import LandingAgent, LandingWorld, NoiseStream, SnapshotError, _Records

SEED = 3


def _fleet(sc, seed=SEED):
    return LandingWorld(sc, seed), {u.id: LandingAgent(sc, seed, u.index, sc.policy) for u in sc.uavs()}


def _run(world, agents, ticks) -> list[tuple[int, str, bytes, str]]:
    """Step ``ticks``; every UAV's command (its rotor speeds' bytes and mode) of each tick."""
    out = []
    for k in ticks:
        inputs = world.step(k)
        for uid, inp in inputs.items():
            cmd = agents[uid].tick(inp)
            world.hold(uid, cmd)
            out.append((k, uid, np.asarray(cmd.u).tobytes(), str(cmd.mode)))
    return out


@pytest.mark.parametrize("cut", [1, 37, 409, 900])
def test_a_fleet_restored_mid_flight_flies_on_as_the_uninterrupted_one_to_the_bit(cut):
    """The world and every agent snapshot at tick ``cut`` (through pickle, as a checkpoint carries them),
    restored into a world and agents built again from the scenario and seed: every later command, and each
    UAV's outcome (world's and agent's halves, the Algorithm 1 records included) is the uninterrupted run's.
    Cut 1: before the sensors' first block of draws is used up; 409, 900: after blocks were drawn again
    (4096 draws a block), mid-approach and mid-descent."""
    sc = load_landing("landing-swarm")
    world, agents = _fleet(sc)
    _run(world, agents, range(1, cut + 1))
    w_snap = pickle.loads(pickle.dumps(world.snapshot()))
    a_snap = {u: pickle.loads(pickle.dumps(a.snapshot())) for u, a in agents.items()}
    world2, agents2 = _fleet(sc)
    world2.restore(w_snap)
    for uid, a in agents2.items():
        a.restore(a_snap[uid])
    n = round(sc.max_duration_s / sc.dt_s)
    first = _run(world, agents, range(cut + 1, n + 1))
    second = _run(world2, agents2, range(cut + 1, n + 1))
    assert first == second
    for uid in agents:
        assert world.outcome(uid) == world2.outcome(uid)
        assert agents[uid].outcome() == agents2[uid].outcome()
        assert agents[uid].outcome()["final_mode"] == "LANDED"  # the run went to its end after the cut


def test_an_unrestored_fleet_of_another_seed_differs():
    """The test above could not pass with a restore that did nothing: a fresh world and agents of the same
    seed, stepped on from tick 410 without the snapshot, command otherwise."""
    sc = load_landing("landing-swarm")
    world, agents = _fleet(sc)
    _run(world, agents, range(1, 410))
    world2, agents2 = _fleet(sc)
    assert _run(world, agents, range(410, 430)) != _run(world2, agents2, range(410, 430))


def test_a_world_snapshot_holds_where_the_noise_stream_is_not_its_block():
    """The sensors' draws come in blocks of 4096 (32 kB); a snapshot keeps the generator's state before the
    block and the position in it, so a world of four UAVs snapshots in well under one block."""
    sc = load_landing("landing-swarm")
    world, agents = _fleet(sc)
    _run(world, agents, range(1, 300))
    assert all(len(u.noise.Z) >= NoiseStream.BLOCK for u in world.uavs.values())
    size = len(pickle.dumps(world.snapshot(), protocol=pickle.HIGHEST_PROTOCOL))
    assert size < NoiseStream.BLOCK * 8, size


def test_a_noise_stream_restored_draws_what_the_original_draws():
    a = NoiseStream(np.random.default_rng(7))
    a.ensure(3000)
    a.pos[0] = 2500
    a.ensure(3000)  # a block drawn after the 1596 left over
    a.pos[0] = 17
    st = pickle.loads(pickle.dumps(a.state()))
    b = NoiseStream(np.random.default_rng(7))
    b.restore(st)
    assert np.array_equal(a.Z, b.Z) and a.pos[0] == b.pos[0]
    a.ensure(10_000)
    b.ensure(10_000)  # and both draw the same next block
    assert np.array_equal(a.Z, b.Z)


def test_records_are_pickled_once_merged_past_a_few_chunks_and_read_back_whole():
    rec, other, records = _Records(0), _Records(1), []
    for i in range(1, _Records.MERGE + 1):
        records += [{"i": i, "j": j} for j in range(i)]
        entries = rec.entries(records)
        assert len(entries) == i  # one chunk per call that added records: the earlier ones not pickled again
    assert rec.entries(records) is entries and len(entries) == _Records.MERGE  # nothing new: nothing pickled
    records.append({"i": "last"})
    merged = rec.entries(records)
    assert len(merged) == 1 and merged[0][2] == zlib.crc32(merged[0][1])  # merged, checksummed once
    mixed = [*merged, *other.entries(["a", "b"])]
    assert _Records.load(mixed, 0) == records and _Records.load(mixed, 1) == ["a", "b"]
    assert _Records.load([(tag, data) for tag, data, _ in mixed], 0) == records  # as a checkpoint reads them


def test_a_snapshot_of_another_world_is_refused():
    one = load_landing("landing")
    four = load_landing("landing-swarm")
    with pytest.raises(SnapshotError, match="UAVs"):
        LandingWorld(one, SEED).restore(LandingWorld(four, SEED).snapshot())
    snap = LandingAgent(four, SEED, 0, four.policy).snapshot()
    snap["state"]["arrays"] = snap["state"]["arrays"][:-8]
    with pytest.raises(SnapshotError, match="bytes of arrays"):
        LandingAgent(four, SEED, 0, four.policy).restore(snap)
    snap["state"]["layout"] = "other"
    with pytest.raises(SnapshotError, match="layout"):
        LandingAgent(four, SEED, 0, four.policy).restore(snap)


def test_a_landing_world_refuses_to_resume_from_a_missing_or_foreign_checkpoint(tmp_path):
    """``python -m swarm.world.landing --resume`` reads its checkpoint before it joins a swarm: none there,
    or one of another run (here another seed), is an error naming the file, exit status 3 (the launcher
    then gives up rather than resume from it); nothing is resumed."""
    import subprocess
    import sys

    from swarm.transport.checkpoint import CheckpointFile, checkpoint_path
    from swarm.world.landing import _run_id

    def resume(seed: int) -> subprocess.CompletedProcess:
        args = [sys.executable, "-m", "swarm.world.landing", "landing-swarm", "--seed", str(seed),
                "--checkpoint-dir", str(tmp_path), "--resume", "--connect", "tcp/127.0.0.1:9"]  # fmt: skip
        return subprocess.run(args, capture_output=True, text=True, timeout=120)

    r = resume(0)
    assert r.returncode == 3 and f"checkpoint {checkpoint_path(tmp_path)}: no such file" in r.stderr, r.stderr
    sc = load_landing("landing-swarm")
    ids = [u.id for u in sc.uavs()]
    f = CheckpointFile(checkpoint_path(tmp_path))
    f.write({"run": _run_id(sc, 7, sc.policy, ids, "lockstep"), "tick": 5,
             "world": LandingWorld(sc, 7).snapshot()})  # fmt: skip
    f.close()
    r = resume(0)
    assert r.returncode == 3 and "of another run: seed 7 (this world: 0)" in r.stderr, r.stderr
    assert "resumed" not in r.stderr and "Traceback" not in r.stderr
