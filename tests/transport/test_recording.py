"""Recording (issue 16): a launched lockstep docking recorded (`swarm launch --record`: a `swarm record`
child on the launcher's router), read back with the plain `mcap` reader; the counts per key equal an
independent subscriber's (which counts each entry of a lockstep bundle under its own key, as the recorder
writes it: docs/protocol.md, "Bundles"); the payloads decode with plain msgpack; record -> replay -> record
gives the same payloads in the same order; a truncated or corrupt file is refused naming the file and the
offset, without hanging."""

from __future__ import annotations

import collections
import sys
import threading

import msgpack
import pytest
from mcap.reader import make_reader

from swarm.errors import LogError
from swarm.transport.keys import Keys
from swarm.transport.recording import read_recording
from swarm.transport.session import ZenohArgs, open_session
from tests.transport.procs import Procs, free_port, loopback, wait_until

PY = [sys.executable, "-m", "swarm.cli.main"]


def _router(procs: Procs, endpoint: str):
    proc = procs.start([*PY, "router", "--listen", endpoint])
    proc.wait_for_line(r"^router listening on ", 60.0)
    return proc


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """One lockstep docking launched with `--record` (its recorder, on the launcher's router session, is
    subscribed before the run starts), counted by this test's own subscriber on an outside router that the
    launcher's router connects to (subscribed before the launch)."""
    d = tmp_path_factory.mktemp("rec")
    ns, ep = f"rec-{free_port()}", loopback(free_port())
    keys = Keys(ns)
    counts: collections.Counter = collections.Counter()
    lock = threading.Lock()

    def count(sample) -> None:
        key = str(sample.key_expr)
        keys_ = [key]
        if key.endswith("/bundle"):  # a lockstep world's bundle: recorded as its entries, each on its own key
            obj = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
            base = key.rsplit("/", 1)[0]
            keys_ = [
                f"{ns}/world/truth" if t == "TruthBatch" else f"{base}/{t.lower()}" for t in obj["types"]
            ]
        with lock:
            for k in keys_:
                counts[k] += 1

    with Procs() as procs:
        _router(procs, ep)
        with open_session(ZenohArgs(mode="client", connect=(ep,))) as session:
            session.declare_subscriber(keys.everything(), count)
            launch = procs.start([*PY, "launch", "docking", "--headless", "--until-docked", "--namespace", ns,
                                  "--connect", ep, "--listen", loopback(free_port()),
                                  "--record", str(d / "run.mcap")])  # fmt: skip
            assert launch.wait(300.0) == 0, launch.output()
            with lock:
                seen = dict(counts)
    assert "recording to" in launch.output()
    return {"path": d / "run.mcap", "counts": seen, "ns": ns, "dir": d}


def test_every_key_on_the_wire_has_its_channel_and_its_count(recorded):
    with open(recorded["path"], "rb") as fh:  # the plain mcap reader
        reader = make_reader(fh)
        summary = reader.get_summary()
        by_topic = collections.Counter(ch.topic for _, ch, _ in reader.iter_messages())
    raw = {ch.topic for ch in summary.channels.values() if ch.message_encoding == "msgpack"}
    assert raw == set(recorded["counts"])
    assert {t: n for t, n in by_topic.items() if t in raw} == recorded["counts"]
    views = {
        ch.topic: summary.schemas[ch.schema_id].name
        for ch in summary.channels.values()
        if ch.topic not in raw
    }
    assert views == {
        "/tf": "foxglove.FrameTransforms",
        "/events": "foxglove.Log",
        "/scene": "foxglove.SceneUpdate",
    }
    ns, c = recorded["ns"], recorded["counts"]
    poses = sum(c[f"{ns}/agent/{v}/{k}"] for v in ("chaser", "target") for k in ("truth", "estimate"))
    # the pose view at most 20 Hz per frame: estimates (100 Hz) keep every 5th sample, truth (50 Hz, every
    # 20 ms) every 3rd (16.7 Hz), for two vehicles
    seconds = max(m.log_time_ns for m in read_recording(recorded["path"])[0]) / 1e9
    expect = 2 * (20.0 + 50.0 / 3.0) * seconds
    assert 0.98 * expect <= by_topic["/tf"] <= 1.02 * expect + 4 < poses
    assert by_topic["/events"] == sum(n for t, n in c.items() if t.endswith("/event"))
    ns = recorded["ns"]
    for key in (
        f"{ns}/agent/chaser/imu",
        f"{ns}/agent/chaser/estimate",
        f"{ns}/world/clock",
        f"{ns}/world/event",
    ):
        assert by_topic[key] > 0, key


def test_payloads_decode_with_plain_msgpack_and_log_time_is_swarm_time(recorded):
    msgs, meta = read_recording(recorded["path"])
    last_t = {}
    for m in msgs:
        obj = msgpack.unpackb(m.payload, raw=False)
        assert isinstance(obj, dict) and obj["v"] == 2 and isinstance(obj["type"], str)
        if "t_s" in obj:
            assert m.log_time_ns == round(obj["t_s"] * 1e9)
            last_t[m.key] = obj["t_s"]
    assert meta["run_start"]["scenario"] == "docking" and meta["run_start"]["clock"] == "lockstep"
    assert meta["recorder"]["namespace"] == recorded["ns"] and "version" in meta["recorder"]
    assert "run_end" in meta


def test_record_replay_record_gives_the_same_payloads_in_the_same_order(recorded, tmp_path):
    ep = loopback(free_port())
    again = tmp_path / "again.mcap"
    with Procs() as procs:
        _router(procs, ep)
        # --until-end: the recorder stops 0.5 s after the replayed run_end reaches it, not when the replay
        # says it has sent everything (the router may still be forwarding the last messages then: a
        # SIGINT at that moment lost the last 5 of ~2700 messages once in a full suite)
        rec = procs.start([*PY, "record", str(again), "--namespace", recorded["ns"], "--until-end",
                           "--mode", "client", "--connect", ep])  # fmt: skip
        rec.wait_for_line(r"^recording ", 60.0)
        rep = procs.start([*PY, "replay", str(recorded["path"]), "--speed", "inf", "--mode", "client",
                           "--connect", ep])  # fmt: skip
        assert rep.wait(300.0) == 0, rep.output()
        n = sum(recorded["counts"].values())
        wait_until(lambda: f"sent {n} messages" in rep.output(), 10.0, "the replay's summary")
        assert rec.wait(60.0) == 0, rec.output()  # (it stopped itself once the run's end was in)
    first, _ = read_recording(recorded["path"])
    second, _ = read_recording(again)
    assert [(m.key, m.payload) for m in second] == [(m.key, m.payload) for m in first]


def test_a_truncated_or_corrupt_recording_is_refused_naming_file_and_offset(recorded, tmp_path):
    data = recorded["path"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(
        LogError, match=r"cut\.mcap: not a complete MCAP recording: .* \(reading stopped at byte \d+ of \d+\)"
    ):
        read_recording(cut)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all" * 10)
    with pytest.raises(LogError, match=r"bad\.mcap: not a complete MCAP recording"):
        read_recording(bad)
    with pytest.raises(LogError, match=r"nowhere\.mcap: cannot read"):
        read_recording(tmp_path / "nowhere.mcap")


def test_a_fresh_agent_fed_the_recorded_sensors_reproduces_the_recorded_estimates_bit_for_bit(recorded):
    """Regression testing of flight code against a recording: a new chaser agent process (lockstep, the
    recorded run's scenario and seed) gets only what the chaser consumed, republished from the file (its
    imu, uwb and vision, the target's estimates, the world's events and clock) paced by its own commands
    (`--lockstep chaser`: as the world's barrier; blasted at full speed, samples were lost on the way);
    every estimate it publishes equals the recorded one byte for byte."""
    ns = recorded["ns"]
    ep = loopback(free_port())
    ours: dict[int, bytes] = {}
    lock = threading.Lock()

    def keep(sample) -> None:
        payload = sample.payload.to_bytes()
        with lock:
            ours[msgpack.unpackb(payload)["tick"]] = payload

    kinds = ("agent/chaser/imu", "agent/chaser/uwb", "agent/chaser/vision", "agent/target/estimate",
             "world/event", "world/clock")  # fmt: skip
    inputs = ",".join(f"{ns}/{k}" for k in kinds)
    with Procs() as procs:
        _router(procs, ep)
        with open_session(ZenohArgs(mode="client", connect=(ep,))) as session:
            session.declare_subscriber(f"{ns}/agent/chaser/estimate", keep)
            agent = procs.start([sys.executable, "-m", "agents", "--id", "chaser", "--clock", "lockstep",
                                 "docking", "--seed", "0", "--namespace", ns, "--mode", "client",
                                 "--connect", ep])  # fmt: skip
            agent.wait_for_line(r"agent chaser ready", 300.0)
            rep = procs.start([*PY, "replay", str(recorded["path"]), "--speed", "inf", "--only", inputs,
                               "--lockstep", "chaser", "--namespace", ns, "--mode", "client",
                               "--connect", ep])  # fmt: skip
            assert rep.wait(300.0) == 0, rep.output()
            msgs, _ = read_recording(recorded["path"])
            want = {
                msgpack.unpackb(m.payload)["tick"]: m.payload
                for m in msgs
                if m.key == f"{ns}/agent/chaser/estimate"
            }
            wait_until(lambda: len(ours) >= len(want), 60.0, "every estimate of the fresh agent")
    with lock:
        got = dict(ours)
    assert set(got) == set(want)
    different = [k for k in sorted(want) if got[k] != want[k]]
    assert not different, (
        f"{len(different)} of {len(want)} estimates differ, the first at tick {different[0]}"
    )


def test_swarm_sim_mcap_writes_what_the_launched_processes_published(recorded, tmp_path):
    """`swarm sim docking --mcap FILE`: the in-process run written as its processes would have published it
    in lockstep (the same encoders, swarm.transport.wire) holds, on every vehicle key, the same
    payloads in the same order as the launched run's recording of the same seed."""
    from swarm.scenario import load_scenario
    from swarm.sim.docking import run_docking
    from swarm.transport.wire import DockingTap

    ns = recorded["ns"]
    sim = tmp_path / "sim.mcap"
    res = run_docking(load_scenario("docking"), seed=0, record_series=False, tap=DockingTap(sim, 0, ns))
    assert res["chasers"]["chaser"]["docked"]
    heard, _ = read_recording(recorded["path"])
    wrote, meta = read_recording(sim)

    def by_key(msgs):
        out: dict[str, list[bytes]] = {}
        for m in msgs:
            # vehicle keys; the agents' end-of-run summaries carry their process's CPU time and counters
            if "/agent/" in m.key and msgpack.unpackb(m.payload).get("kind") != "summary":
                out.setdefault(m.key, []).append(m.payload)
        return out

    a, b = by_key(heard), by_key(wrote)
    kinds = {k.rsplit("/", 1)[1] for k in a}
    assert kinds == {"imu", "uwb", "vision", "truth", "command", "estimate", "guidance", "event"}
    assert set(a) == set(b)
    for key in sorted(a):
        first = next((i for i, (x, y) in enumerate(zip(a[key], b[key], strict=False)) if x != y), None)
        assert first is None and len(a[key]) == len(b[key]), (
            key, len(a[key]), len(b[key]), first,
            None if first is None else (msgpack.unpackb(a[key][first]), msgpack.unpackb(b[key][first])),
        )  # fmt: skip
    assert meta["recorder"]["source"] == "swarm sim" and "run_end" in meta
    assert {m.key for m in wrote} >= {f"{ns}/world/clock", f"{ns}/world/event"}
