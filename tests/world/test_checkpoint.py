"""The world's checkpoint: a world resumed from the file continues as the uninterrupted one, bit for bit;
a file of another run, torn, damaged or missing is refused with an error naming it.

Oracle: self-consistency against the same world run without interruption (same scenario, seed and
commands), compared on the encoded samples each tick publishes (the bytes the agents receive) and on the
world's full snapshot. The ticks compared cross a refill of the pre-drawn gyro noise (every 1024 ticks),
AHRS samples and camera frames, the parts a checkpoint re-draws or restores rather than copies.
"""

from __future__ import annotations

import subprocess
import sys
import threading

import numpy as np
import pytest

from swarm.core.guidance import docking_geometry
from swarm.scenario import load_scenario
from swarm.step.world import NOISE_BLOCK, World
from swarm.transport import checkpoint
from swarm.transport.checkpoint import CheckpointError
from swarm.transport.keys import Keys
from swarm.transport.messages import Vision, decode
from swarm.transport.process import ClockSpec
from swarm.world.process import WorldProcess, unconfirmed_ticks
from tests.transport.procs import REPO

SEED = 3
RESUME_AT = NOISE_BLOCK - 9  # the gyro's noise block is re-drawn 9 ticks after the restart


@pytest.fixture(scope="module")
def sc():
    return load_scenario("docking")


def _world(sc, directory, seed=SEED, resume=None) -> WorldProcess:
    """A world process without a session: the tests drive its tick by hand, as :meth:`WorldProcess.run`.
    The chaser starts 0.3 m in front of its docked pose, facing the target: its camera sees the markers
    (every frame draws camera noise), as it does not from the scenario's start."""
    wp = WorldProcess(sc, seed, None, Keys("ckpt"), ClockSpec(), threading.Event(),
                      checkpoint_dir=directory, resume=resume)  # fmt: skip
    if resume is None:
        xt, xc = wp.world.x["target"], wp.world.x["chaser"]
        n_nav, p_docked, q_dock = docking_geometry(sc.guidance, xt[0:3], xt[6:10])
        xc[0:3], xc[6:10] = p_docked + 0.3 * n_nav, q_dock
    return wp


def _tick(wp: WorldProcess) -> list[tuple[str, str, bytes]]:
    """One tick as the run loop does it: commands (some nozzles on, from a stream fixed by the tick),
    step, encode, checkpoint before publishing. Returns the tick's samples."""
    k = wp.world.k
    rng = np.random.default_rng(k)
    for vid in wp.ids:
        n = wp.world.command_size(vid)
        wp.world.set_command(vid, rng.uniform(0.0, 0.002, n) * (rng.random(n) < 0.3))
    frames = wp.world.step()
    wp._new_tick(wp.world.k, frames)
    wp._checkpoint()
    return wp._sensors


def _same_snapshot(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        if key == "blocks":
            for name in a[key]:
                sa, sb = a[key][name], b[key][name]
                assert (sa is None) == (sb is None), name
                if sa is not None:
                    assert sa[0] == sb[0] and sa[1:] == sb[1:], name
        else:
            assert a[key] == b[key], key


def test_a_resumed_world_publishes_the_same_samples_as_the_uninterrupted_one(sc, tmp_path):
    a = _world(sc, tmp_path)
    for _ in range(RESUME_AT):
        _tick(a)
    state = checkpoint.load(checkpoint.checkpoint_path(tmp_path))
    b = _world(sc, tmp_path / "unused", resume=state)
    assert b.resumed_at == RESUME_AT == b.world.k
    assert b._sensors == a._sensors  # the samples of the resumed tick, published again as they were
    _same_snapshot(b.world.snapshot(), a.world.snapshot())
    markers_seen = 0
    for k in range(RESUME_AT + 1, RESUME_AT + 40):
        got, want = _tick(b), _tick(a)
        assert got == want, f"tick {k}: the samples differ"
        markers_seen += sum(decode(p, Vision).seen for kind, _, p in want if kind == "vision")
    assert markers_seen > 0 and a.world.k > NOISE_BLOCK  # camera frames and a noise refill were compared
    _same_snapshot(b.world.snapshot(), a.world.snapshot())
    np.testing.assert_array_equal(b.world.X, a.world.X)


class _Put:
    """A publisher that records what it is given, in order, with its key's (kind, vehicle)."""

    def __init__(self, out: list, kind: str, vid: str) -> None:
        self.out, self.kind, self.vid = out, kind, vid

    def put(self, payload: bytes) -> None:
        self.out.append((self.kind, self.vid, payload))


def _announced(wp: WorldProcess) -> list[tuple[str, str, bytes]]:
    """What a resumed world publishes on its sample keys when it announces its resumption."""
    sent: list = []
    wp._pub = lambda kind, vid: _Put(sent, kind, vid)
    wp._world_event = lambda *args: None
    wp._publish_clock = lambda k: None
    wp._announce_resume(wp.world.k)
    return sent


def test_a_resumed_world_publishes_again_the_earlier_ticks_some_process_may_lack(sc, tmp_path):
    """A world killed at tick ``m`` may take with it samples of the ticks before ``m`` that its Zenoh
    session had not sent (an agent lacking one waits for it forever: restarted as hung, the run parts from
    the simulation). The resumed world publishes them again, in tick order, then tick ``m``'s: exactly the
    samples those ticks published, for the ``unconfirmed_ticks`` ticks before ``m``."""
    a = _world(sc, tmp_path)
    published = {}
    for _ in range(25):
        sensors = _tick(a)
        published[a.world.k] = sensors
    m = a.world.k
    b = _world(sc, tmp_path / "unused", resume=checkpoint.load(checkpoint.checkpoint_path(tmp_path)))
    window = unconfirmed_ticks(sc)
    assert window == sc.control_every("chaser") < m  # a control period: the world waits for its commands
    want = [s for k in range(m - window, m + 1) for s in published[k]]
    assert _announced(b) == want
    assert {kind for kind, _, _ in want} >= {"imu", "vision", "truth_batch"}  # every kind of sample
    # and the resumed world keeps them on: its next checkpoint holds the ticks after m - window
    _tick(b)
    c = _world(sc, tmp_path / "c", resume=checkpoint.load(checkpoint.checkpoint_path(tmp_path / "unused")))
    published[m + 1] = b._sensors
    assert _announced(c) == [s for k in range(m + 1 - window, m + 2) for s in published[k]]


def test_a_mothership_serves_each_slot_once_from_a_resumed_worlds_truths_and_fills_a_lost_one(sc, tmp_path):
    """The mothership's side of a resumption: it got the truths up to a slot, lost the next one with the
    killed world, then gets the resumed world's ticks again (served slots among them). It serves every
    slot once, in order, with the ranges of a mothership that got each truth once, and counts the served
    slots it was sent again as such, not as invalid messages."""
    from mothership.process import MothershipProcess
    from swarm.transport.messages import TruthBatch

    a = _world(sc, tmp_path)
    batches = {}
    for _ in range(24):
        for kind, _, payload in _tick(a):
            if kind == "truth_batch":
                batches[a.world.k] = payload
    slots = sorted(batches)

    def mothership() -> tuple[MothershipProcess, list]:
        ms = MothershipProcess(sc, SEED, None, Keys("ckpt"), threading.Event())
        sent: list = []
        ms.pub_uwb = {v: _Put(sent, "uwb", v) for v in ms.ids}
        return ms, sent

    def feed(ms, ticks) -> None:
        for k in ticks:
            ms._on_truth_batch("ckpt/world/truth", decode(batches[k], TruthBatch))

    once, want = mothership()
    feed(once, slots)
    resumed, got = mothership()
    lost = slots[8]
    feed(resumed, slots[:8])  # then the truths of slot `lost` go with the killed world
    feed(resumed, [k for k in slots if lost - 10 <= k])  # the resumed world's ticks from 10 before it on
    assert got == want and resumed.slots == once.slots == len(slots)
    assert resumed.served_again == sum(1 for k in slots if lost - 10 <= k < lost) > 0
    assert resumed.drops.total == 0


def test_a_tdma_channel_widens_the_unconfirmed_ticks_by_a_frame_and_a_uwb_period(sc):
    """On a TDMA channel an agent's last range may be a frame older than its last command, so the
    mothership's truths since then are not confirmed by it."""
    pairs = load_scenario("docking", overrides={"uwb.tdma": True}).with_pairs(4)
    frame_s = pairs.uwb.tdma_slot_s * 8  # 8 tags: a frame of 8 slots
    uwb_every = pairs.every(pairs.uwb.rate_hz)
    assert unconfirmed_ticks(pairs) >= unconfirmed_ticks(sc.with_pairs(4)) + frame_s / pairs.dt_s + uwb_every


def test_the_referee_state_and_faults_are_restored(sc, tmp_path):
    a = _world(sc, tmp_path)
    _tick(a)
    a.referee.done[0] = a.referee.ko_flag[0] = True
    a.referee.closest[0], a.missing_ticks = 0.123, 4
    a.modes["chaser"] = "DOCK"
    a.world.take_commands(1, {"chaser": (np.zeros(10), "ALIGN")})  # the schedule records the mode
    a.world.add_fault("camera_loss", 2.0, 1.0, ["chaser"])
    a.world.add_fault("nlos_burst", 2.5, 1.0, a.ids, 0.3)
    a._delays["chaser"] = [(1.0, 2.0, 0.03)]
    a._checkpoint()
    b = _world(sc, tmp_path / "unused", resume=checkpoint.load(checkpoint.checkpoint_path(tmp_path)))
    assert (b.done, b.missing_ticks, b.modes) == ({"chaser"}, 4, a.modes)
    assert b.referee.snapshot() == a.referee.snapshot()
    assert b.world.faults.state() == a.world.faults.state()
    assert b.world.camera_loss == a.world.camera_loss and b._delays == a._delays
    assert b.world.radio_env(3.0) == (False, 0.3)
    assert b.barrier.next_tick == 1  # commands of tick 0 are stale for the resumed world


def test_a_world_resumes_only_its_own_runs_checkpoint(sc, tmp_path):
    a = _world(sc, tmp_path)
    _tick(a)
    state = checkpoint.load(checkpoint.checkpoint_path(tmp_path))
    with pytest.raises(CheckpointError, match=r"checkpoint .*of another run: seed 3 \(this world: 4\)"):
        _world(sc, tmp_path, seed=4, resume=state)
    other = load_scenario("docking", overrides={"uwb.sigma_m": 0.2})
    with pytest.raises(CheckpointError, match=r"of another run: fingerprint"):
        _world(other, tmp_path, resume=state)


@pytest.mark.parametrize("ticks", [12, 13])  # the newest slot is the file's last (cut short) or its first
def test_a_world_killed_while_writing_a_checkpoint_resumes_from_the_one_before(sc, tmp_path, ticks):
    """The file holds two slots written in turn: a write cut short (the world killed in it) leaves the
    checkpoint of the tick before, whose samples the world had not published yet, and the resumed world
    continues from there as the uninterrupted one did."""
    a = _world(sc, tmp_path)
    published = {}
    for _ in range(ticks):
        sensors = _tick(a)
        published[a.world.k] = sensors
    path = checkpoint.checkpoint_path(tmp_path)
    newest = checkpoint.load(path)
    seq, slot = newest["checkpoint"]
    assert newest["tick"] == a.world.k == ticks == seq
    data = bytearray(path.read_bytes())
    capacity = int.from_bytes(data[8:16], "little")
    cut = 16 + slot * capacity + 200  # the newest slot's write stopped 200 bytes in
    if slot == 1:
        data = data[:cut]
    else:
        data[cut : 16 + capacity] = bytes(16 + capacity - cut)
    path.write_bytes(bytes(data))
    before = checkpoint.load(path)
    m = ticks - 1
    assert before["tick"] == m and before["checkpoint"] == (seq - 1, 1 - slot)
    b = _world(sc, tmp_path / "b", resume=before)
    assert b.world.k == m and b._sensors == published[m]
    assert _announced(b) == [
        s for k in range(m - unconfirmed_ticks(sc), m + 1) if k >= 1 for s in published[k]
    ]
    c = _world(sc, tmp_path / "c")  # an uninterrupted world: tick m + 1 again, and on
    for _ in range(m):
        _tick(c)
    for _ in range(3):
        assert _tick(b) == _tick(c)


def test_a_checkpoint_file_is_written_in_place_one_slot_after_the_other(tmp_path):
    """A write goes to the slot not holding the newest checkpoint, in the same file (no new file, no
    rename: the cheap path); a resumed writer goes on from the slot it read, to the other one first, so the
    checkpoint it resumed from stays whole until a newer one is; a state that outgrows the slots makes a
    new file twice its size."""
    path = tmp_path / "world.ckpt"
    f = checkpoint.CheckpointFile(path)
    samples = [checkpoint.sample_entry(t, bytes([t]) * 100) for t in range(3)]
    f.write({"tick": 1}, samples[:1])
    inode = path.stat().st_ino
    f.write({"tick": 2}, samples[:2])
    f.write({"tick": 3}, samples)
    st = checkpoint.load(path)
    assert path.stat().st_ino == inode and st["tick"] == 3 and st["checkpoint"] == (3, 0)
    assert st["samples"] == [(t, bytes([t]) * 100) for t in range(3)]
    f.close()
    g = checkpoint.CheckpointFile(path, after=st["checkpoint"])
    g.write({"tick": 4})
    assert checkpoint.load(path)["checkpoint"] == (4, 1) and path.stat().st_ino == inode
    big = {"tick": 5, "pad": bytes(3 * g.capacity)}
    g.write(big)
    assert path.stat().st_ino != inode and checkpoint.load(path)["pad"] == big["pad"]
    assert g.capacity >= 2 * len(big["pad"])
    g.write({"tick": 6})
    assert checkpoint.load(path)["tick"] == 6 and sorted(p.name for p in tmp_path.iterdir()) == ["world.ckpt"]
    g.close()


def test_a_checkpoint_write_replaces_the_file_whole(sc, tmp_path):
    a = _world(sc, tmp_path)
    _tick(a)
    path = checkpoint.checkpoint_path(tmp_path)
    first = path.read_bytes()
    _tick(a)
    assert path.read_bytes() != first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["world.ckpt"]  # no temporary file left over


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (lambda b: b[: len(b) // 2], "torn: "),
        (lambda b: b[:-1] + bytes([b[-1] ^ 1]), "damaged: CRC-32 mismatch"),
        (lambda b: b"not a checkpoint at all", "not a world checkpoint"),
        (lambda b: b"", "not a world checkpoint"),
    ],
)
def test_a_torn_or_damaged_checkpoint_is_refused_naming_the_file(sc, tmp_path, damage, why):
    _tick(_world(sc, tmp_path))
    path = checkpoint.checkpoint_path(tmp_path)
    path.write_bytes(damage(path.read_bytes()))
    with pytest.raises(CheckpointError, match=f"checkpoint {path}: {why}"):
        checkpoint.load(path)


def test_a_missing_checkpoint_is_refused_naming_the_file(tmp_path):
    with pytest.raises(CheckpointError, match=f"checkpoint {tmp_path}/world.ckpt: no such file"):
        checkpoint.load(checkpoint.checkpoint_path(tmp_path))


def test_the_world_process_exits_3_without_joining_on_a_torn_checkpoint(sc, tmp_path):
    """The launcher tells a bad checkpoint from a crash by the exit status, and gives up on the world."""
    _tick(_world(sc, tmp_path))
    path = checkpoint.checkpoint_path(tmp_path)
    path.write_bytes(path.read_bytes()[:100])
    cmd = [sys.executable, "-m", "swarm.world", "docking", "--seed", str(SEED), "--checkpoint-dir",
           str(tmp_path), "--resume", "--mode", "client", "--connect", "tcp/127.0.0.1:9"]  # fmt: skip
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=REPO)
    assert r.returncode == checkpoint.EXIT_BAD_CHECKPOINT == 3, r.stderr
    assert f"swarm world: error: checkpoint {path}: torn: " in r.stderr and "not resuming" in r.stderr
    assert "Traceback" not in r.stderr and "ready" not in r.stdout


def test_resume_without_a_checkpoint_directory_is_a_flag_error():
    cmd = [sys.executable, "-m", "swarm.world", "docking", "--resume"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=REPO)
    assert r.returncode == 2 and "--resume needs --checkpoint-dir" in r.stderr, r.stderr


def test_a_world_snapshot_does_not_copy_the_noise_blocks(sc):
    """A snapshot holds the streams' states at the block's draw, not the ~1024 pre-drawn rows: small."""
    w = World(sc, SEED)
    for _ in range(5):
        w.step(build_frames=False)
    assert w.gyro_noise.nbytes >= NOISE_BLOCK * 6 * 8 * len(w.ids)
    snap = w.snapshot()
    assert sum(len(v) for v in snap.values() if isinstance(v, bytes)) < 2000
    restored = World(sc, SEED)
    restored.restore(snap)
    np.testing.assert_array_equal(restored.gyro_noise, w.gyro_noise)
    np.testing.assert_array_equal(restored.ahrs_noise, w.ahrs_noise)


def test_a_snapshot_has_every_streams_state_as_it_is_now():
    """The snapshot keeps the streams' states from the last one and refreshes those drawn from since (the
    noise blocks' refills, the camera's pixels): at every tick they equal the streams' own states. PnP
    camera (it draws from the camera stream every frame), the chaser in front of the markers, across a
    refill of the gyro noise."""
    sc = load_scenario("docking", {"camera.model": "pnp"})
    w = World(sc, SEED)
    xt, xc = w.x["target"], w.x["chaser"]
    n_nav, p_docked, q_dock = docking_geometry(sc.guidance, xt[0:3], xt[6:10])
    xc[0:3], xc[6:10] = p_docked + 0.3 * n_nav, q_dock
    camera0 = w.rng["chaser", "camera"].bit_generator.state
    gyro0 = w.rng["chaser", "gyro"].bit_generator.state
    for k in range(NOISE_BLOCK + 20):
        w.step(build_frames=True)
        if k % 7 == 0 or k >= NOISE_BLOCK - 5:
            assert w.snapshot()["rng"] == {key: g.bit_generator.state for key, g in w.rng.items()}, k
    assert w.rng["chaser", "camera"].bit_generator.state != camera0  # the pixels drew noise
    assert w.rng["chaser", "gyro"].bit_generator.state != gyro0  # a refill drew the next block


def test_pickled_streams_are_pickled_again_only_when_they_change_and_restore_alike(sc):
    """A world process's snapshot carries the streams' states and noise blocks as pickles made again only
    when a stream was drawn from or a block drawn: the same bytes object between, new ones after a refill;
    each form restores the same world."""
    import pickle

    w = World(sc, SEED)
    w.step(build_frames=False)
    first = w.snapshot(pickled_streams=True)
    w.step(build_frames=False)
    second = w.snapshot(pickled_streams=True)
    assert second["rng"] is first["rng"] and second["blocks"] is first["blocks"]  # nothing drawn: reused
    assert pickle.loads(second["rng"]) == w.snapshot()["rng"]
    for _ in range(NOISE_BLOCK):  # across a refill of the gyro noise: new states, a new block
        w.step(build_frames=False)
    third = w.snapshot(pickled_streams=True)
    assert third["rng"] != first["rng"] and third["blocks"] != first["blocks"]
    assert pickle.loads(third["rng"]) == {key: g.bit_generator.state for key, g in w.rng.items()}
    plain = w.snapshot()
    a, b = World(sc, SEED), World(sc, SEED)
    a.restore(third)  # pickled form
    b.restore(plain)  # dict form
    for _ in range(30):  # each restored world and the original, stepped alike, draw the same samples
        for x in (a, b, w):
            x.step(build_frames=False)
        np.testing.assert_array_equal(a.gyro_out, w.gyro_out)
        np.testing.assert_array_equal(b.gyro_out, w.gyro_out)
    np.testing.assert_array_equal(a.X, w.X)


def test_a_process_draws_smaller_noise_blocks_of_the_same_samples(sc, tmp_path):
    """A world process refills its pre-drawn noise PROCESS_NOISE_BLOCK rows at a time (a 1024-row refill of
    128 vehicles stalled a tick by ~16 ms), and a mothership its radios' likewise: the samples are those of
    the in-process run's 1024-row blocks, tick for tick, across several refills of each stream."""
    from mothership.process import MothershipProcess
    from swarm.step.radio import NOISE_BLOCK as RADIO_BLOCK
    from swarm.step.radio import UwbNetwork
    from swarm.transport.process import PROCESS_NOISE_BLOCK

    wp = _world(sc, tmp_path)
    ms = MothershipProcess(sc, SEED, None, Keys("ckpt"), threading.Event())
    assert wp.world.noise_block == ms.network.noise_block == PROCESS_NOISE_BLOCK
    assert PROCESS_NOISE_BLOCK < min(NOISE_BLOCK, RADIO_BLOCK)
    small, big = World(sc, SEED), World(sc, SEED)
    small.noise_block = PROCESS_NOISE_BLOCK
    net_small, net_big = UwbNetwork(sc, SEED), UwbNetwork(sc, SEED)
    net_small.noise_block = PROCESS_NOISE_BLOCK
    ahrs_every = small.ahrs_every
    ticks = (PROCESS_NOISE_BLOCK + 3) * ahrs_every  # the AHRS stream refills too
    for _ in range(ticks):
        for w in (small, big):
            w.step(build_frames=False)
        np.testing.assert_array_equal(small.gyro_out, big.gyro_out)
        np.testing.assert_array_equal(small.ahrs_out, big.ahrs_out)
        got = net_small.step(small.k, small.k * sc.dt_s, small.X)
        want = net_big.step(big.k, big.k * sc.dt_s, big.X)
        assert got == want, small.k
    assert small.gyro_noise.shape[1] == PROCESS_NOISE_BLOCK < big.gyro_noise.shape[1]
    assert net_small.noise.shape[1] == PROCESS_NOISE_BLOCK < net_big.noise.shape[1]
