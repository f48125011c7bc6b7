"""The agent host's wiring between its vehicles (no Zenoh: the processes are built, not opened)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from agents.host import AgentHost
from agents.process import AgentProcess
from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.process import ClockSpec


def _host(ids, sc, clock="lockstep"):
    cond, ready, stop = threading.Condition(), set(), threading.Event()
    spec, n = ClockSpec.parse(clock), len(ids)
    procs = [
        AgentProcess(sc, v, 0, "mdp", None, Keys("t"), spec, stop, hosted=n, cond=cond, ready=ready)
        for v in ids
    ]
    return AgentHost(procs, None, Keys("t"), stop), {p.id: p for p in procs}


def test_a_chaser_takes_its_targets_estimates_from_the_host_only_when_the_target_is_hosted_there():
    """chaser0 and target0 share the host: target0 hands its estimates to chaser0, which subscribes to none;
    chaser1's target is in another process: chaser1 subscribes to it as before, and no one hands it over."""
    sc = load_scenario("docking").with_pairs(2)
    _, p = _host(["chaser0", "target0", "chaser1"], sc)
    assert p["chaser0"].target_local and p["target0"].local_chasers == [p["chaser0"]]
    assert not p["chaser1"].target_local
    assert p["chaser0"].local_chasers == [] and p["chaser1"].local_chasers == []


def test_a_host_refuses_vehicles_that_do_not_share_its_condition():
    sc = load_scenario("docking")
    stop = threading.Event()
    procs = [AgentProcess(sc, v, 0, "mdp", None, Keys("t"), ClockSpec.parse("lockstep"), stop, hosted=2,
                          cond=threading.Condition(), ready=set()) for v in ("chaser", "target")]  # fmt: skip
    with pytest.raises(ValueError, match="share one condition"):
        AgentHost(procs, None, Keys("t"), stop)


class _Publisher:
    """A publisher's ``put`` and ``matching_status`` (whether any subscriber matches its key)."""

    def __init__(self, matching: bool) -> None:
        self.matching_status = type("Status", (), {"matching": matching})()
        self.sent: list[bytes] = []

    def put(self, payload: bytes) -> None:
        self.sent.append(bytes(payload))


@pytest.mark.parametrize("listened", [False, True])
def test_an_estimate_is_encoded_only_for_a_subscriber_and_always_handed_to_a_hosted_chaser(listened):
    """A headless swarm's estimates have no subscriber but the chaser's: they are not encoded (Zenoh would
    drop them unsent). A subscriber (a viewer, a recorder) gets every one of a chaser, the bytes of
    encode_estimate; a chaser in the host gets its target's message either way. A target's estimate goes out
    only on the ticks before those its chaser reads it (camera every 5 ticks, control every 10 here):
    estimate(4) does, estimate(3) does not, to a subscriber or to the chaser."""
    from swarm.step.agent import VehicleAgent
    from swarm.step.world import initial_truth
    from swarm.transport.messages import Estimate, decode
    from swarm.transport.wire import estimate_payload

    sc = load_scenario("docking")
    assert sc.every(sc.camera.rate_hz) == 5 and sc.control_every("chaser") == 10
    _, p = _host(["chaser", "target"], sc)
    for v, proc in p.items():
        x = initial_truth(sc, 0, v)
        proc.agent = VehicleAgent(sc, v, x[0:3], x[3:6], x[6:10], np.full(9, 1e-4), "mdp")
        proc.pub_estimate = _Publisher(listened)
        proc._estimate_listened = listened  # as Zenoh's matching listener keeps it
    got = []
    p["chaser"].assembler.add = lambda msg, source: got.append((msg, source))
    payloads = {}
    for k in (3, 4):
        payloads[k] = {v: estimate_payload(p[v].agent, k) for v in ("chaser", "target")}
        for v in ("chaser", "target"):
            p[v]._publish_estimate(k)
    chaser_sent = [payloads[3]["chaser"], payloads[4]["chaser"]]
    assert p["chaser"].pub_estimate.sent == (chaser_sent if listened else [])
    assert p["target"].pub_estimate.sent == ([payloads[4]["target"]] if listened else [])
    ((msg, source),) = got
    assert source == "target" and msg.tick == 4
    want = decode(payloads[4]["target"], Estimate)
    assert np.array_equal(msg.p_nav, want.p_nav) and np.array_equal(msg.cov, want.cov)


class _StampedPublisher(_Publisher):
    """A publisher that also keeps each ``put``'s attachment (``None`` when it was given none)."""

    def __init__(self) -> None:
        super().__init__(True)
        self.attachments: list[bytes | None] = []

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        super().put(payload)
        self.attachments.append(attachment)


def test_an_estimate_carries_the_publication_stamp_of_its_ticks_imu_and_only_that():
    """Each imu's stamp (its subscriber's ``published_ns``) rides on the estimate of its tick as a msgpack
    attachment; a tick whose imu was unstamped sends none; a target's estimates that do not go out (not
    read by its chaser) still forget their stamps, and a vehicle that sends none for a while (re-initialising)
    keeps only the newest ``_STAMPS_KEPT``."""
    import msgpack

    from agents import process as agent_process
    from swarm.step.agent import VehicleAgent
    from swarm.step.world import initial_truth

    sc = load_scenario("docking")
    _, p = _host(["chaser", "target"], sc, clock="realtime")
    for v, proc in p.items():
        x = initial_truth(sc, 0, v)
        proc.agent = VehicleAgent(sc, v, x[0:3], x[3:6], x[6:10], np.full(9, 1e-4), "mdp")
        proc.pub_estimate = _StampedPublisher()
        proc._estimate_listened = True
        proc.local_chasers = []  # (each as if alone: the target publishes, no hand-over)
    chaser, target = p["chaser"], p["target"]
    ns = 1_764_400_000_000_000_000
    for k in (1, 2, 3):
        for proc in (chaser, target):
            proc._on_sensor("t/imu", _imu(k), None if k == 2 else ns + k)
            proc._publish_estimate(k)
    unpack = [None if a is None else msgpack.unpackb(a) for a in chaser.pub_estimate.attachments]
    assert unpack == [{"imu_published_ns": ns + 1}, None, {"imu_published_ns": ns + 3}]
    assert target.pub_estimate.attachments == []  # estimates 1 to 3 are not read by the chaser: none sent
    assert not chaser._imu_published and not target._imu_published  # nothing kept past its tick
    kept = agent_process._STAMPS_KEPT
    for k in range(10, 10 + 3 * kept):  # a vehicle that sends no estimate meanwhile
        chaser._on_sensor("t/imu", _imu(k), ns + k)
    assert sorted(chaser._imu_published) == list(range(10 + 2 * kept, 10 + 3 * kept))


def test_a_free_running_agent_fuses_a_late_range_and_frame_as_the_tick_would_have():
    """Late fusion (free-running): the range and the camera frame of tick k that came after its estimate
    went out are fused before tick k + 1, with the values the tick would have fused; a re-initialising
    agent (rejoin) takes a late range into its initial fix. Lockstep agents have no late fusion."""
    from swarm.step.agent import VehicleAgent
    from swarm.step.world import initial_truth
    from swarm.transport.messages import Uwb, Vision
    from swarm.transport.wire import filter_counts

    sc = load_scenario("docking")
    host, p = _host(["chaser", "target"], sc, clock="realtime")
    assert host.grace_s == 0.0
    assert p["chaser"].assembler.late_ticks == round(sc.agent.late_fusion_s / sc.dt_s) > 0
    assert _host(["chaser", "target"], sc)[1]["chaser"].assembler.late_ticks is None  # lockstep
    x = initial_truth(sc, 0, "chaser")
    proc = p["chaser"]
    twins = [VehicleAgent(sc, "chaser", x[0:3], x[3:6], x[6:10], np.full(9, 1e-4), "mdp") for _ in range(2)]
    proc.agent, ref = twins
    tgt = initial_truth(sc, 0, "target")
    from swarm.step.agent import TargetEstimate

    for a in twins:
        a.set_target_estimate(TargetEstimate(0.0, tgt[0:3], tgt[6:10], np.eye(3) * 1e-6))
        a.on_imu(0.05, 0.01, np.zeros(3), x[6:10])
    r = float(np.linalg.norm(np.asarray(sc.anchors_m[1]) - x[0:3])) + 0.01
    pts = np.array([[0.01 * i, 0.01 * (i % 2), 0.3] for i in range(len(ref.markers_target))])
    vis = Vision(tick=5, t_s=0.05, target_id="target", face="+x", kind="features", data=pts,
                 marker_ids=tuple(range(len(pts))))  # fmt: skip
    proc.fuse_late([Uwb(tick=4, t_s=0.04, anchor_id=1, range_m=r), Uwb(tick=6, t_s=0.06, anchor_id=2,
                                                                        range_m=None), vis])  # fmt: skip
    ref.on_uwb(1, r)
    ref.on_vision(0.05, "features", pts)
    assert filter_counts(proc.agent) == filter_counts(ref)
    counts = filter_counts(ref)  # one range and one frame reached the filter (whatever its gate said)
    fused = [sum(v for n, v in counts.items() if n.startswith(kind)) for kind in ("range", "features")]
    assert fused == [1, 1]
    np.testing.assert_array_equal(proc.agent.est.X, ref.est.X)
    np.testing.assert_array_equal(proc.agent.est.P, ref.est.P)
    rejoining = p["target"]
    rejoining.agent = None
    rejoining.fuse_late([Uwb(tick=2, t_s=0.02, anchor_id=0, range_m=1.0)])
    assert rejoining._init_ranges == {0: 1.0}


def _recording_host(process):
    """A host of the target alone whose vehicle's steps are recorded (``process(inp)``), its run started."""
    sc = load_scenario("docking")
    host, p = _host(["target"], sc)
    proc = p["target"]
    proc._started.set()  # the world announced the run
    finished = threading.Event()
    proc.process, proc.flush = process, lambda: None
    proc.done, proc.finish = (lambda now: finished.is_set()), (lambda: True)
    return host, proc, finished


def _imu(k: int):
    from swarm.transport.messages import Imu

    return Imu(tick=k, t_s=0.01 * k, dt_s=0.01, gyro_body=np.zeros(3))


def test_a_host_of_one_steps_a_tick_on_the_thread_whose_message_made_it_ready():
    """A host of one vehicle (a process each) runs the round on the subscriber's thread that completed the
    tick, not on its loop's thread (one thread hand-off less per tick); its loop still ends the run. A host
    of several keeps one thread: its callbacks run on Zenoh's receiving threads."""
    seen = []
    host, proc, finished = _recording_host(lambda inp: seen.append((inp.tick, threading.get_ident())))
    assert host.inline and proc.on_news == host.on_news
    ended = []
    loop = threading.Thread(target=lambda: ended.append(host._loop()))
    loop.start()
    try:
        deadline = threading.Event()
        while not seen and not deadline.wait(0.01):  # tick 0 (no samples) goes on the first round
            pass
        subscriber = threading.Thread(target=proc._on_sensor, args=("t/agent/target/imu", _imu(1)))
        subscriber.start()
        subscriber.join(5.0)
        assert [k for k, _ in seen] == [0, 1]
        assert seen[1][1] == subscriber.ident != loop.ident  # stepped by the message's own thread
        assert seen[0][1] == loop.ident
    finally:
        finished.set()
        loop.join(5.0)
    assert ended == [True] and not loop.is_alive()
    assert not _host(["chaser", "target"], load_scenario("docking"))[0].inline


def test_a_failure_on_a_subscribers_thread_is_raised_by_the_hosts_loop():
    """A vehicle's step that raises on the subscriber's thread does not vanish into Zenoh's callback: the
    host's loop raises it (the process exits 1 and its supervisor restarts it), and no round runs after."""

    stepped = []

    def process(inp):
        stepped.append(inp.tick)
        if inp.tick == 1:
            raise RuntimeError("tick 1 failed")

    host, proc, finished = _recording_host(process)
    raised = []

    def loop():
        try:
            host._loop()
        except RuntimeError as exc:
            raised.append(exc)

    t = threading.Thread(target=loop)
    t.start()
    try:
        proc._on_sensor("t/agent/target/imu", _imu(1))  # this thread: the subscriber's; it returns
        t.join(5.0)
        assert [str(e) for e in raised] == ["tick 1 failed"] and not t.is_alive()
        proc._on_sensor("t/agent/target/imu", _imu(2))
        assert stepped == [0, 1]  # the failure is kept: nothing more is stepped
    finally:
        finished.set()
        t.join(5.0)


def test_a_host_of_one_steps_what_the_runs_start_made_ready_on_the_clocks_thread():
    """Tick 0 waits for the world's run to start; the clock that starts it (a shared subscriber's callback)
    steps it at once on its own thread, not at the loop's next look (IDLE_S later). No loop thread runs
    here: whatever is stepped is stepped inside the calls."""
    from swarm.transport.messages import Clock

    seen = []
    host, proc, finished = _recording_host(lambda inp: seen.append(inp.tick))
    proc._started.clear()  # the world has not announced the run yet
    host._live = [proc]
    host.ready.update(host._by_asm)
    proc._on_sensor("t/agent/target/imu", _imu(1))
    assert seen == []  # not ticking before the run starts
    host._on_clock("t/world/clock", Clock(tick=0, t_s=0.0, state="running", seed=0))
    assert seen == [0, 1]  # the run's start made ticks 0 and 1 ready, stepped on this thread
    finished.set()


def test_the_worlds_batch_gives_each_hosted_vehicle_its_own_row_and_no_other():
    """The world's ``world/imu`` batch (agent hosts) reaches each vehicle of a host as the ``imu`` of its
    own key would have: its row, as an :class:`Imu`; a row for a vehicle hosted elsewhere is nobody's here."""
    from swarm.transport.messages import Imu, ImuBatch

    sc = load_scenario("docking").with_pairs(2)
    host, p = _host(["chaser0", "target0"], sc)
    got = {vid: [] for vid in p}
    for vid, proc in p.items():
        proc._on_sensor = lambda key, msg, published_ns=None, vid=vid: got[vid].append((key, msg))
    gyro = np.arange(12.0).reshape(4, 3)
    q = np.array([[0.0, 0.0, 0.0, 1.0]])
    batch = ImuBatch(5, 0.05, 0.01, ("chaser1", "target0", "chaser0", "target1"), gyro, ("chaser0",), q)
    host._on_batch("t/world/imu", batch)
    assert got["chaser0"] == [("t/world/imu", Imu(5, 0.05, 0.01, gyro[2], q[0]))]
    assert got["target0"] == [("t/world/imu", Imu(5, 0.05, 0.01, gyro[1]))]


def test_the_motherships_batch_gives_each_hosted_vehicle_its_own_range_and_no_other():
    """The mothership's ``mothership/uwb`` batch (agent hosts) reaches each hosted vehicle as the ``uwb`` of
    its own key would have, a lost reply (nil) included; another host's vehicle's entry is nobody's here."""
    from swarm.transport.messages import Uwb, UwbBatch

    sc = load_scenario("docking").with_pairs(2)
    host, p = _host(["chaser0", "target0"], sc)
    got = {vid: [] for vid in p}
    for vid, proc in p.items():
        proc._on_sensor = lambda key, msg, published_ns=None, vid=vid: got[vid].append((key, msg))
    batch = UwbBatch(4, 0.04, ("target1", "chaser0", "target0"), (2, 0, 3), (1.25, None, 0.75))
    host._on_batch("t/mothership/uwb", batch)
    assert got == {"chaser0": [("t/mothership/uwb", Uwb(4, 0.04, 0, None))],
                   "target0": [("t/mothership/uwb", Uwb(4, 0.04, 3, 0.75))]}  # fmt: skip


def test_the_worlds_vision_batch_gives_each_hosted_chaser_its_own_frame_and_drops_a_bad_one_alone():
    """The world's ``world/vision`` batch (agent hosts) reaches each hosted chaser as the ``vision`` of its
    own key would have; another host's chaser's entry is nobody's here, and an entry that does not decode
    is counted in the host's drops, naming the vehicle, without losing the other frames."""
    from swarm.transport.messages import Vision, VisionBatch, encode

    sc = load_scenario("docking").with_pairs(3)
    host, p = _host(["chaser0", "target0", "chaser2"], sc)
    got = {vid: [] for vid in p}
    for vid, proc in p.items():
        proc._on_sensor = lambda key, msg, published_ns=None, vid=vid: got[vid].append((key, msg))
    frame = Vision(10, 0.1, "target0", "+x", "features", np.full((6, 3), 0.25), (0, 1, 2, 3, 4, 5))
    other = Vision(10, 0.1, "target1", "+x", "features", np.zeros((0, 3)), ())
    batch = VisionBatch(10, 0.1, ("chaser1", "chaser0", "chaser2"), (encode(other), encode(frame), b"junk"))
    host._on_batch("t/world/vision", batch)
    assert got == {"chaser0": [("t/world/vision", frame)], "target0": [], "chaser2": []}
    assert host.shared_drops.count("t/world/vision") == 1


@pytest.mark.parametrize("clock", ["lockstep", "realtime"])
def test_a_round_steps_the_vehicles_that_command_on_their_tick_first(clock):
    """Staggered controllers (``swarm.stagger_control``): of a round's ticks, those on which a vehicle sends
    a command are stepped first, the others after them in host order; the estimates (lockstep: after every
    command of the round) follow the same order."""
    from swarm.transport.lockstep import TickInputs

    sc = load_scenario("docking", {"swarm": {"stagger_control": True}}).with_pairs(3)
    ids = list(sc.vehicles)
    host, p = _host(ids, sc, clock)
    k = 12
    commanding = [v for v in ids if p[v].commands_at(k)]
    assert 0 < len(commanding) < len(ids)  # the stagger spreads the six vehicles over the control period
    steps = []
    for vid, proc in p.items():
        proc._started.set()
        proc.assembler.poll_round = lambda grace, vid=vid: ((), TickInputs(tick=k), False)
        proc.process = lambda inp, vid=vid: steps.append(("process", vid))
        proc.flush = lambda vid=vid: steps.append(("flush", vid))
    host._live = list(host.procs)
    host.ready.update(host._by_asm)
    assert host._round()
    order = commanding + [v for v in ids if v not in commanding]
    assert steps == [("process", v) for v in order] + [("flush", v) for v in order]


def test_a_host_of_several_sends_a_rounds_commands_in_one_batch_before_stepping_the_others():
    """A free-running host of several vehicles sends the commands its vehicles decided in a round as one
    CommandBatch (``agent/<first id>/commands``), as soon as the last vehicle that commands on the tick is
    stepped: the world gets them before the other vehicles' steps; each entry is the vehicle's own command
    payload. A host of one, and a lockstep host, keep each vehicle's own key."""
    from swarm.transport.lockstep import TickInputs
    from swarm.transport.messages import Command, CommandBatch, decode, encode

    sc = load_scenario("docking", {"swarm": {"stagger_control": True}}).with_pairs(3)
    ids = list(sc.vehicles)
    host, p = _host(ids, sc, "realtime")
    k = 12
    commanding = [v for v in ids if p[v].commands_at(k)]
    steps, sent = [], []

    class Pub:
        def put(self, payload):
            sent.append(len(steps))
            steps.append(("sent", decode(payload, CommandBatch)))

    host._pub_commands = Pub()
    payloads = {v: encode(Command(k, k * 0.01, np.zeros(3), "HOLD", np.zeros(3), np.zeros(3))) for v in ids}
    for vid, proc in p.items():
        proc._started.set()
        proc.assembler.poll_round = lambda grace, vid=vid: ((), TickInputs(tick=k), False)

        def process(inp, vid=vid, proc=proc):
            steps.append(("process", vid))
            if proc.commands_at(inp.tick):
                proc.command_sink.append((vid, payloads[vid]))

        proc.process, proc.flush = process, lambda: None
    host._live = list(host.procs)
    host.ready.update(host._by_asm)
    assert host._round()
    assert [s[1] for s in steps if s[0] == "process"] == commanding + [v for v in ids if v not in commanding]
    (at,) = sent  # one message, right after the commanding vehicles' steps
    assert at == len(commanding)
    batch = steps[at][1]
    assert batch.ids == tuple(commanding) and batch.commands == tuple(payloads[v] for v in commanding)
    assert (
        host._commands == []
    )  # the round's list is emptied, not replaced: the vehicles keep appending to it
    assert all(proc.command_sink is host._commands for proc in p.values())
    _, q = _host(["chaser0"], sc, "realtime")
    assert q["chaser0"].command_sink is None  # a host of one: the vehicle's own command key
    _, q = _host(ids, sc, "lockstep")
    assert all(proc.command_sink is None for proc in q.values())  # lockstep: each vehicle's own key


@pytest.mark.parametrize("listened", [False, True])
def test_guidance_is_encoded_only_for_a_subscriber(listened):
    """A control tick's guidance goes to whoever subscribes to it (the launcher to its chasers', a viewer
    to any vehicle's) and is not encoded for no one: a headless swarm's targets send none. It goes out with
    the estimate (flush), after the host's round has sent its commands. The mode events and the command go
    out either way."""
    from swarm.step.agent import VehicleAgent
    from swarm.step.world import initial_truth
    from swarm.transport.messages import Guidance, decode

    sc = load_scenario("docking")
    _, p = _host(["chaser", "target"], sc)
    proc = p["target"]
    x = initial_truth(sc, 0, "target")
    proc.agent = VehicleAgent(sc, "target", x[0:3], x[3:6], x[6:10], np.full(9, 1e-4), "mdp")
    proc.pub_guidance, proc.pub_event = _Publisher(listened), _Publisher(listened)
    proc._guidance_listened = listened  # as Zenoh's matching listener keeps it
    cmd = proc.agent.control(0.0, proc.agent.control_dt)
    proc._commanded(0, cmd)
    sent = proc.pub_guidance.sent
    assert sent == []  # after the round's commands (flush): it kept a host's commands waiting
    proc.flush()
    assert len(sent) == (1 if listened else 0)
    proc.flush()  # once
    assert len(sent) == (1 if listened else 0)
    if listened:
        assert decode(sent[0], Guidance).mode == "STATION"


def test_a_rounds_commands_are_packed_with_each_vehicle_once_per_message_in_order():
    """A host that caught up on two ticks of a vehicle in one round sends its second command in the next
    message, after the first; a round whose commands would pass the payload limit is split, none lost."""
    from swarm.transport.messages import MAX_PAYLOAD_BYTES, CommandBatch, decode, pack_entries

    entries = [("a", b"1"), ("b", b"2"), ("a", b"3"), ("c", b"4")]
    got = [decode(p, CommandBatch) for p in pack_entries(entries, CommandBatch)]
    assert [(b.ids, b.commands) for b in got] == [(("a", "b"), (b"1", b"2")), (("a", "c"), (b"3", b"4"))]
    big = [(f"v{i}", bytes(MAX_PAYLOAD_BYTES // 3)) for i in range(4)]
    got = [decode(p, CommandBatch) for p in pack_entries(big, CommandBatch)]
    assert [b.ids for b in got] == [("v0", "v1"), ("v2", "v3")]


@pytest.mark.parametrize("clock", ["realtime", "lockstep"])
def test_a_free_running_agent_alone_takes_its_range_frame_and_target_estimate_at_its_imu(clock):
    """A free-running vehicle alone in its process (a real Zenoh session here) takes its ranges, frames and
    target estimates from queues at each imu, not as they come: nothing reaches its assembler before the
    imu, and all of it, with the imu, once the imu is in. In lockstep each input is taken as it comes (a
    lockstep tick waits for every one of them)."""
    import time

    from swarm.step.world import initial_truth
    from swarm.transport.messages import Imu, Uwb, Vision, encode
    from swarm.transport.session import ZenohArgs, open_session
    from swarm.transport.wire import estimate_payload
    from tests.transport.procs import free_port, loopback, wait_until

    sc = load_scenario("docking")
    keys, ep = Keys(f"queued{clock}"), loopback(free_port())
    stop = threading.Event()
    with (
        open_session(ZenohArgs(mode="peer", listen=(ep,))) as mine,
        open_session(ZenohArgs(mode="peer", connect=(ep,))) as world,
    ):
        proc = AgentProcess(sc, "chaser", 0, "mdp", mine, keys, ClockSpec.parse(clock), stop, hosted=1,
                            cond=threading.Condition(), ready=set())  # fmt: skip
        proc.open()
        assert len(proc._queued) == (3 if clock == "realtime" else 0)  # range, frame, target estimate
        kept: list[tuple[str, int]] = []
        add = proc.assembler.add
        proc.assembler.add = lambda msg, source=None: (
            kept.append((type(msg).__name__, msg.tick)) or add(msg, source)
        )

        def put(key, payload):
            pub = world.declare_publisher(key)
            wait_until(lambda: pub.matching_status.matching, 5.0, f"the agent's subscriber on {key}")
            pub.put(payload)

        from swarm.step.agent import VehicleAgent

        x = initial_truth(sc, 0, "target")
        target = VehicleAgent(sc, "target", x[0:3], x[3:6], x[6:10], np.full(9, 1e-4), "mdp")
        pts = np.array([[0.01 * i, 0.01 * (i % 2), 0.3] for i in range(4)])
        put(keys.uwb("chaser"), encode(Uwb(tick=10, t_s=0.1, anchor_id=1, range_m=1.0)))
        frame = Vision(tick=10, t_s=0.1, target_id="target", face="+x", kind="features", data=pts,
                       marker_ids=(0, 1, 2, 3))  # fmt: skip
        put(keys.vision("chaser"), encode(frame))
        put(keys.estimate("target"), estimate_payload(target, 9))
        time.sleep(0.3)
        early = sorted(kept)
        put(keys.imu("chaser"), encode(Imu(tick=10, t_s=0.1, dt_s=0.01, gyro_body=[0.0, 0.0, 0.0])))
        wait_until(lambda: ("Imu", 10) in kept, 5.0, "the imu")
        everything = [("Estimate", 9), ("Imu", 10), ("Uwb", 10), ("Vision", 10)]
        if clock == "realtime":
            assert early == [] and sorted(kept) == everything
            assert kept[-1] == ("Imu", 10)  # the queued inputs first, then the imu that makes the tick
        else:
            assert early == [("Estimate", 9), ("Uwb", 10), ("Vision", 10)] and sorted(kept) == everything
        assert proc.drops.total == 0
        stop.set()


def _simulate_wakes(arrival, n_ticks: int, every: int, phase: int, period: float, margin: float):
    """Drive a :class:`WakePlanner` against imu arrival times ``arrival[k]`` (monotonic seconds) as the
    pacer does: wait for its wake, take what has come, poll while it says so. Returns, per control tick, when
    the wake that took its imu was, and the time of every wake (polls included)."""
    from agents.host import WakePlanner

    newest_at = lambda now: max((k for k in range(1, n_ticks + 1) if arrival[k] <= now), default=None)  # noqa: E731
    state = {"newest": None}

    def next_control_tick() -> int:
        k = 1 if state["newest"] is None else state["newest"] + 1
        return k + (phase - k) % every

    plan = WakePlanner(period, margin, next_control_tick)
    now, wakes, took_at = arrival[1] - 0.05, [], {}
    while state["newest"] is None or state["newest"] < n_ticks - every:
        now = max(now, plan.next(state["newest"], now))
        polled = 0
        while True:
            wakes.append(now)
            newest = newest_at(now)
            if newest is not None:
                for k in range(1 if state["newest"] is None else state["newest"] + 1, newest + 1):
                    if (k - phase) % every == 0:
                        took_at[k] = now
                state["newest"] = newest
            if plan.took(newest, now, polled):
                break
            polled += 1
            now += plan.poll_s()
        now += 1e-5  # (the round's own time)
    return took_at, wakes


@pytest.mark.parametrize("stall", [False, True])
def test_a_control_rate_wake_learns_when_the_imu_comes_and_takes_each_control_tick_within_two_margins(stall):
    """``agent.wake_at_control``: the planner learns the imu's arrival from its wakes. Simulated world:
    tick k's imu comes at 1.3 ms past its slot, with up to 0.6 ms of jitter; with ``stall``, the world
    stands still for a second after tick 3 and then catches up at 8 times its pace (some 120 ticks), as a
    world starting among 30 processes did (the planner polls for its control tick meanwhile). After the
    first 50 control periods every control tick's imu is taken within two margins of its arrival (a margin
    past its expected time, plus a poll), at no more than ~4 wakes per period. A planner that learnt only
    from its control wakes stayed ~17 ticks late for good after such a stall: the first arrival it timed
    was of a tick still behind the world's schedule, and its fusing wakes, which found everything in,
    taught it nothing."""
    period, margin, every, phase, n = 0.01, 0.0005, 10, 3, 2000
    rng = np.random.default_rng(0)
    t0 = 1000.0
    arrival = {k: t0 + k * period + 0.0013 + rng.uniform(0, 0.0006) for k in range(1, n + 1)}
    if stall:
        for k in range(4, n + 1):
            arrival[k] = max(arrival[k], t0 + 3 * period + 1.0 + (k - 4) * period / 8)
    took_at, wakes = _simulate_wakes(arrival, n, every, phase, period, margin)
    steady = [k for k in sorted(took_at) if k > 50 * every]
    assert len(steady) >= 140 and arrival[50 * every] < t0 + 50 * every * period + 0.002  # (caught up)
    delays = np.array([took_at[k] - arrival[k] for k in steady])
    assert delays.min() >= 0 and delays.max() <= 2 * margin + 1e-4, delays.max()
    start = arrival[50 * every]
    per_period = sum(1 for w in wakes if w > start) / len(steady)
    assert per_period <= 4.5, per_period


def test_a_control_rate_agent_queues_its_imu_too_and_takes_everything_when_drained():
    """With ``agent.wake_at_control`` a free-running vehicle alone in its process (a real Zenoh session) does
    not take even its imu as it comes: its four inputs wait in Zenoh's queues (the imu's first) until the
    pacer drains them, and then the imu comes before the range of its tick. The next control tick is the
    first of the vehicle's after the newest imu taken."""
    import time

    from swarm.transport.messages import Imu, Uwb, encode
    from swarm.transport.session import ZenohArgs, open_session
    from tests.transport.procs import free_port, loopback, wait_until

    sc = load_scenario("docking", {"agent.wake_at_control": True})
    keys, ep = Keys("ctlwake"), loopback(free_port())
    stop = threading.Event()
    with (
        open_session(ZenohArgs(mode="peer", listen=(ep,))) as mine,
        open_session(ZenohArgs(mode="peer", connect=(ep,))) as world,
    ):
        proc = AgentProcess(sc, "chaser", 0, "mdp", mine, keys, ClockSpec.parse("realtime"), stop, hosted=1,
                            cond=threading.Condition(), ready=set())  # fmt: skip
        assert proc.wake_at_control and proc.next_control_tick() == 1 + (proc.control_phase - 1) % 10
        proc.open()
        assert len(proc._queued) == 4  # imu, range, frame, target estimate
        kept: list[tuple[str, int]] = []
        add = proc.assembler.add
        proc.assembler.add = lambda msg, source=None: (
            kept.append((type(msg).__name__, msg.tick)) or add(msg, source)
        )
        uwb = encode(Uwb(tick=10, t_s=0.1, anchor_id=1, range_m=1.0))
        imu = encode(Imu(tick=10, t_s=0.1, dt_s=0.01, gyro_body=[0.0] * 3))
        for key, payload in ((keys.uwb("chaser"), uwb), (keys.imu("chaser"), imu)):
            pub = world.declare_publisher(key)
            wait_until(lambda pub=pub: pub.matching_status.matching, 5.0, f"the agent's subscriber on {key}")
            pub.put(payload)
        time.sleep(0.3)
        assert kept == [] and proc.newest_imu is None  # nothing taken as it came
        proc.drain_inputs()
        assert kept == [("Imu", 10), ("Uwb", 10)] and proc.newest_imu == 10
        assert proc.next_control_tick() == 11 + (proc.control_phase - 11) % 10
        stop.set()


def test_lockstep_and_agent_hosts_ignore_the_control_rate_wake():
    sc = load_scenario("docking", {"agent.wake_at_control": True})
    for clock, hosted in (("lockstep", 1), ("realtime", 2)):
        cond = threading.Condition()
        proc = AgentProcess(sc, "chaser", 0, "mdp", None, Keys("x"), ClockSpec.parse(clock),
                            threading.Event(), hosted=hosted, cond=cond, ready=set())  # fmt: skip
        assert not proc.wake_at_control, (clock, hosted)


@pytest.mark.parametrize("stopping", [False, True])
def test_a_round_whose_publication_the_closing_session_refuses_ends_quietly_once_stopping(stopping, caplog):
    """A host of one steps its vehicle on a Zenoh thread: a publication into the session the main thread
    closes meanwhile raises ``zenoh.ZError``. Once the swarm is stopping (here the launcher's ``stopping``
    event heard) that ends the rounds with no error and no failure; in a running swarm it is the host's
    failure, logged with its traceback (the host exits 1 and is restarted)."""
    import logging
    from types import SimpleNamespace

    import zenoh

    host, p = _host(["chaser"], load_scenario("docking"))
    chaser = p["chaser"]
    chaser._started.set()
    chaser.assembler.poll_round = lambda _grace: ([], SimpleNamespace(tick=1), False)

    def closed(_inp) -> None:
        raise zenoh.ZError("session closed")

    chaser.process = closed
    host._live = [chaser]
    host.ready.add(chaser.assembler)
    if stopping:
        assert host.stopping.hear("stopping")
    with caplog.at_level(logging.DEBUG):
        host._drain()
    errors = [r for r in caplog.records if r.levelno >= logging.WARNING]
    if stopping:
        assert host._failure is None and not errors
    else:
        assert isinstance(host._failure, zenoh.ZError)
        assert [r.getMessage() for r in errors] == ["chaser: agent failed at tick 1"] and errors[0].exc_info
