"""The world process: truth dynamics and on-board sensors of every vehicle, over Zenoh.

A thin adapter around the world step (:class:`swarm.step.world.World`) and the referee
(:class:`swarm.step.referee.Referee`), in the tick order of docs/architecture.md, so that a lockstep run is
the in-process run:

1. wait until every agent of the scenario and the mothership are alive (liveliness), then announce the
   run (``world/event`` ``run_start``, ``world/clock`` tick 0 ``running``);
2. tick ``k``: take the live agents' ``command(k)`` (an agent commands on its control ticks and the world
   holds it in between; lockstep: wait for those whose control tick ``k`` is, or a timeout; realtime: the
   latest of each, taken from the commands' queues at the tick: ``QueuedSubscriber`` of
   :mod:`swarm.transport.session`) into the world, whose fault schedule opens the windows the chasers'
   modes trigger, judge each chaser on the truth (keep-out, contact: ``agent/<id>/event``), then step to
   ``k + 1`` and publish, per vehicle, ``truth(k+1)`` (with its tag's radio environment, which the
   mothership's radios apply), its camera frame ``vision(k+1)`` on camera ticks (chasers; zero markers
   when the target is not in view) and ``imu(k+1)``;
3. the run ends when every chaser has made contact, at ``sim.max_duration_s``, on a ``reset``/``new_seed``
   run control or a stop signal: ``run_end`` (with each vehicle's total impulse), then clock ``stopped``.

An agent whose liveliness token goes is dropped from the lockstep and its nozzles closed (a vehicle whose
computer died does not keep firing); it joins again with its first command for a tick not yet stepped.

With a checkpoint directory (``--checkpoint-dir``) the world writes its complete state at every tick ``k``
(:mod:`swarm.transport.checkpoint`) *before* it publishes that tick's sensors, so no process ever saw a sample
of a tick later than the checkpoint. An unpaced lockstep world keeps the samples of the ticks up to the next
one an agent commands on and then sends them as one ``Bundle`` per receiver (docs/protocol.md, "Bundles"); it
writes its checkpoint just before it sends them, with the same guarantee. A world restarted with ``--resume``
continues from it: it announces ``world/event`` ``world_resumed`` and its clock, re-publishes tick ``k``'s
samples and those of the ticks before it that some process may not have received (:func:`unconfirmed_ticks`:
a killed world loses what its Zenoh session had not sent yet; an agent drops those it already has) and waits
for the commands due at tick ``k`` (an agent that already sent its command re-sends it on
``world_resumed``). A lockstep run with a world killed and resumed is the uninterrupted run, bit for bit.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
import pickle
import queue
import threading
import time
from collections import deque
from pathlib import Path

import numpy as np

from swarm.scenario import Scenario
from swarm.step.radio import tdma_channel
from swarm.step.referee import Referee
from swarm.step.world import World
from swarm.transport import checkpoint
from swarm.transport.checkpoint import CheckpointError
from swarm.transport.keys import Keys
from swarm.transport.lockstep import CommandBarrier
from swarm.transport.messages import (
    CLOCK_EVERY,
    NEW_RUN_COMMANDS,
    Clock,
    Command,
    CommandBatch,
    DropCounter,
    Event,
    Fault,
    RunControl,
    batch_rows,
    encode,
    pack_bundle,
)
from swarm.transport.process import PROCESS_NOISE_BLOCK, ClockSpec, declare_reliable
from swarm.transport.session import (
    QueuedSubscriber,
    declare_liveliness,
    subscribe_decoded,
    watch_liveliness,
)
from swarm.transport.stopping import Stopping, process_name, wait_for_stop
from swarm.transport.wire import batch_samples, contact_event, keepout_event, world_sensors

_LOG = logging.getLogger("swarm.world")


COMMAND_QUEUE = 4096
"""Commands a free-running world keeps between two ticks (its queues' capacity): 128 vehicles at 10 Hz for
over 3 s; past it the oldest go, and only the newest of each vehicle is used."""


class WorldProcess:
    """One run of the world over an open Zenoh session (module docstring)."""

    def __init__(
        self,
        scenario,
        seed: int,
        session,
        keys: Keys,
        clock: ClockSpec,
        stop: threading.Event,
        *,
        step_timeout_s: float = 5.0,
        start_timeout_s: float = 180.0,
        clock_every: int = CLOCK_EVERY,
        process_id: str = "world",
        checkpoint_dir: str | Path | None = None,
        resume: dict | None = None,
        pace: ClockSpec | None = None,
        batch: bool = False,
        bundles: bool = True,
    ) -> None:
        """``pace``: a lockstep world that also never runs ahead of this wall clock (realtime or scaled:N;
        every command is still waited for, so the run is the unpaced one); ``batch``: every vehicle's
        imu of a tick in one ``world/imu`` message and the chasers' camera frames in one ``world/vision``
        (agent hosts, docs/protocol.md "Rates"). The truths of a UWB slot tick go to the mothership in one
        ``world/truth`` either way, and on each vehicle's key only while a viewer subscribes to it;
        ``checkpoint_dir``: write the state there every tick (``None``: never); ``resume``: a state
        :func:`swarm.transport.checkpoint.load` read, to continue from (:class:`CheckpointError` if it is
        not a state of this run: another scenario, seed or vehicle set); ``bundles``: an unpaced lockstep
        world without ``batch`` sends the samples of the ticks up to the next one an agent commands on as
        one ``Bundle`` per receiver (docs/protocol.md, "Bundles"), and writes its checkpoint only before it
        sends them."""
        sc = scenario
        self.sc, self.seed, self.session, self.keys, self.clock, self.stop = (
            sc,
            seed,
            session,
            keys,
            clock,
            stop,
        )
        self.pace = clock if not clock.lockstep else pace  # the wall clock the ticks keep to, if any
        self.stopping = Stopping(stop)  # a peer's going is then a stop (swarm.transport.stopping)
        self.step_timeout_s = step_timeout_s
        self.start_timeout_s = start_timeout_s
        self.clock_every = max(1, int(clock_every))
        self._between: list[tuple] = []  # (publisher, payload): a tick's truths, until halfway to the next
        self.process_id = process_id
        self.batch = batch
        # a lockstep world's samples wait for the next tick an agent commands on, then leave as one Bundle per
        # receiver: no agent can use a tick before then anyway (its command needs every tick up to it)
        self.bundles = bundles and clock.lockstep and self.pace is None and not batch
        self._bundle: dict[str, list[tuple[str, bytes, int]]] = {}  # per receiver ("": the mothership)
        self._bundle_ticks = 0  # ticks in the pending bundles
        self._viewed: set[str] = set()  # the vehicles whose per-vehicle truth a subscriber matches
        self.world = World(sc, seed)  # with the run's dispersions and its fault schedule
        self.world.noise_block = PROCESS_NOISE_BLOCK
        self.referee = Referee(sc)
        self.ids = list(sc.vehicles)
        self.chasers = sc.chasers
        self._truth_every = sc.every(sc.uwb.rate_hz)  # the UWB slot period [ticks]
        # a bundle holds at most a control period's ticks (the longest): the world flushes at every agent's
        # control tick, and at this bound when no live agent is due (all lost, or all done)
        self._bundle_max = max(sc.control_every(v) for v in self.ids)
        self.drops = DropCounter()
        # each agent commands on its control ticks and the world holds the command in between (the in-process
        # run's World.take_commands takes the vehicles that decided one): the lockstep waits on those ticks
        self.barrier = CommandBarrier(
            self.ids, every={v: sc.control_every(v) for v in self.ids},
            phase={v: sc.control_phase(v) for v in self.ids},
        )  # fmt: skip
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._mothership = False
        self._lost: list[str] = []  # agents seen lost since the main loop last looked
        self._returned: list[str] = []  # awaited agents whose token is back, not yet handed their tick
        self._joining: list[str] = []  # agents handed a tick, in the lockstep from the next one
        self._awaited: set[str] = set()  # lost agents not back yet: a lockstep world waits for them
        self._latest: dict[str, Command] = {}  # realtime: newest command per agent
        self._queued: list[QueuedSubscriber] = []  # free-running: the commands' queues, drained at each tick
        self._controls: queue.Queue[RunControl] = queue.Queue()
        self._faults: queue.Queue[Fault] = queue.Queue()
        self._delays: dict[str, list[tuple[float, float, float]]] = {}  # sensor_delay windows per vehicle
        self._held: list = []  # delayed samples: (release time, seq, kind, vehicle, payload), a heap
        self._held_seq = itertools.count()
        self._delay_rng = np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=(2**16,)))
        self.modes = dict.fromkeys(self.ids, "HOLD")  # each agent's mode, from its last command
        self.missing_ticks = 0  # lockstep ticks stepped without some live agent's command
        self._missed_in_a_row: dict[str, int] = {}  # per agent: its due commands missing since its last one
        # free-running: vehicle-ticks stepped (of vehicles whose agent has commanded), and those stepped
        # with an out-of-date command (the one of the vehicle's last control tick had not come: the one
        # before was held); and the control ticks' commands due, and those that came after their tick
        self.commanded_ticks = 0
        self.late_commands = 0
        self.due_commands = 0
        self.late_due_commands = 0
        self._commanding: set[str] = set()
        self._last_command_tick: dict[str, int] = {}  # free-running: the newest command's tick per agent
        self.state = "running"
        self.ckpt_path = None if checkpoint_dir is None else checkpoint.checkpoint_path(checkpoint_dir)
        if self.ckpt_path is not None:
            self.ckpt_path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        self.ckpt_s = 0.0  # wall time spent writing checkpoints [s], and how many
        self.ckpt_n = 0
        self.ckpt_bytes = 0
        self._ckpt_file: checkpoint.CheckpointFile | None = None
        if self.ckpt_path is not None:
            after = None if resume is None else resume.get("checkpoint")
            self._ckpt_file = checkpoint.CheckpointFile(self.ckpt_path, after=after)
        self._sensors: list[tuple[str, str, bytes]] = []  # the current tick's samples, as published
        self._sensors_entry: tuple | None = None  # ... pickled once, as a checkpoint's samples entry
        # the samples of the ticks before the current one that some process may not have received yet, as
        # checkpoint sample entries (tick, pickled samples, CRC-32): published again by a resumed world
        self._earlier: deque[tuple[int, bytes, int]] = deque(maxlen=unconfirmed_ticks(sc))
        self._wall_before = self._cpu_before = 0.0  # a resumed run's wall and CPU time before the restart
        self._wall0, self._cpu0 = time.perf_counter(), time.process_time()  # reset when the run starts
        self.resumed_at: int | None = None
        self._run_id_cache: dict | None = None
        if resume is not None:
            self._restore(resume)

    # ------------------------------------------------------------------------------ checkpoints

    def _run_id(self) -> dict:
        """What a checkpoint must share with this world to be resumed by it."""
        if self._run_id_cache is None:
            self._run_id_cache = {"scenario": self.sc.name, "fingerprint": checkpoint.fingerprint(self.sc),
                                  "seed": self.seed,
                                  "vehicles": self.ids}  # fmt: skip
        return self._run_id_cache

    def _state(self, wall_s: float, cpu_s: float) -> dict:
        now = time.monotonic()
        return {
            "run": self._run_id(), "tick": self.world.k, "world": self.world.snapshot(pickled_streams=True),
            "modes": dict(self.modes), "referee": self.referee.snapshot(),
            "missing_ticks": self.missing_ticks, "state": self.state,
            "delays": {v: list(w) for v, w in self._delays.items()},
            "delay_rng": self._delay_rng.bit_generator.state,
            "held": [(max(0.0, t - now), kind, vid, payload) for t, _, kind, vid, payload in self._held],
            "wall_s": wall_s, "cpu_s": cpu_s,
        }  # fmt: skip

    def _sensors_sample(self, k: int) -> tuple[int, bytes, int]:
        """The current samples (those of tick ``k``) as a checkpoint's entry, pickled and checksummed once
        per tick: every checkpoint of the tick, then those of the ticks after it while it is an earlier
        one, carry them."""
        if self._sensors_entry is None:
            blob = pickle.dumps(self._sensors, protocol=pickle.HIGHEST_PROTOCOL)
            self._sensors_entry = checkpoint.sample_entry(k, blob)
        return self._sensors_entry

    def _new_tick(self, k: int, frames) -> list[tuple[str, str, bytes]]:
        """Tick ``k``'s samples (:meth:`_encode_tick`) become the current ones, and those of tick ``k - 1``
        an earlier tick's, kept while some process may not have them (:func:`unconfirmed_ticks`)."""
        if self._sensors and self._ckpt_file is not None:  # (kept only for a checkpoint)
            self._earlier.append(self._sensors_sample(k - 1))
        self._sensors, self._sensors_entry = self._encode_tick(k, frames), None
        return self._sensors

    def _checkpoint(self) -> None:
        """Write the state of the current tick (its samples encoded, not yet published), if asked to."""
        if self.ckpt_path is None:
            return
        t0 = time.perf_counter()
        wall = self._wall_before + t0 - self._wall0
        cpu = self._cpu_before + time.process_time() - self._cpu0
        try:
            samples = [*self._earlier, self._sensors_sample(self.world.k)]
            self.ckpt_bytes = self._ckpt_file.write(self._state(wall, cpu), samples)
        except OSError as exc:
            # an older checkpoint would resume behind the agents (they would never send its commands):
            # remove it, so that a restart says "no checkpoint" and the launcher gives up on the world
            _LOG.error("checkpoint %s not written (%s): checkpoints off, this run cannot survive a restart "
                       "of the world", self.ckpt_path, exc)  # fmt: skip
            self._ckpt_file.close()
            self.ckpt_path.unlink(missing_ok=True)
            self.ckpt_path = self._ckpt_file = None
            return
        self.ckpt_s += time.perf_counter() - t0
        self.ckpt_n += 1

    def _restore(self, st: dict) -> None:
        where = f"checkpoint {self.ckpt_path}" if self.ckpt_path is not None else "checkpoint"
        try:
            checkpoint.check_run(where, st["run"], self._run_id())
            self.world.restore(st["world"])
            self.modes.update(st["modes"])
            self.referee.restore(st["referee"])
            self.missing_ticks, self.state = int(st["missing_ticks"]), str(st["state"])
            self._delays = {v: list(w) for v, w in st["delays"].items()}
            self._delay_rng.bit_generator.state = st["delay_rng"]
            now = time.monotonic()
            for left, kind, vid, payload in st["held"]:
                heapq.heappush(self._held, (now + left, next(self._held_seq), kind, vid, payload))
            self._wall_before, self._cpu_before = float(st["wall_s"]), float(st["cpu_s"])
            tick = int(st["tick"])
            self._earlier.clear()
            self._sensors, self._sensors_entry = [], None
            for k_sample, blob in st["samples"]:  # the recent ticks', oldest first, then this tick's
                if int(k_sample) == tick:
                    self._sensors = list(pickle.loads(blob))
                else:
                    self._earlier.append(checkpoint.sample_entry(int(k_sample), blob))
        except CheckpointError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError, pickle.UnpicklingError) as exc:
            raise CheckpointError(f"{where}: not a state this world can resume: {exc!r}") from None
        if tick != self.world.k:
            raise CheckpointError(f"{where}: tick {tick} but its world is at tick {self.world.k}")
        self.barrier.reset(tick)  # commands of earlier ticks are stale; later ones are buffered
        self.resumed_at = tick

    # ------------------------------------------------------------------------------ Zenoh side

    def _on_command(self, key: str, cmd: Command) -> None:
        parsed = self.keys.parse(key)
        self._take_command(key, parsed[1] if parsed else None, cmd)

    def _on_command_batch(self, key: str, msg: CommandBatch) -> None:
        """An agent host's round of commands (``agent/<id>/commands``): each entry taken as the command of
        its vehicle's own key; an entry that does not decode is dropped and counted, naming the vehicle,
        and loses no other vehicle's command."""
        for vid, cmd in batch_rows(msg, key, self.drops):
            self._take_command(key, vid, cmd)

    def _take_command(self, key: str, vid: str | None, cmd: Command) -> None:
        """Vehicle ``vid``'s command (from ``key``): held (free-running) or into the barrier (lockstep)."""
        if vid not in self.world.index:
            self.drops.drop(key, "command: not a vehicle of this scenario")
            return
        n = self.world.command_size(vid)
        if cmd.actuators.shape != (n,):
            why = f"command: actuators has {cmd.actuators.shape[0]} entries, {vid}'s kind takes {n}"
            self.drops.drop(key, why)
            return
        if not self.clock.lockstep:
            with self._lock:
                self._latest[vid] = cmd
            return
        with self._lock:
            live = self.barrier.live
            if vid not in live and vid in self._alive and cmd.tick >= self.barrier.next_tick:
                self.barrier.set_live(live | {vid})  # (re)joins the lockstep
                _LOG.info("agent %s joins the lockstep at tick %d", vid, cmd.tick)
        self.barrier.add(vid, cmd)

    def _on_alive(self, role: str, pid: str, alive: bool) -> None:
        with self._lock:
            if role == "mothership":
                self._mothership = alive
                if not alive:
                    self.stopping.gone(_LOG, process_name(role, pid), "%s lost", process_name(role, pid))
                return
            if role != "agent" or pid not in self.world.index:
                return
            if alive:
                self._alive.add(pid)
                if pid in self._awaited:
                    self._returned.append(pid)  # the main loop hands it the current tick (_await_lost)
                self._awaited.discard(pid)
                return
            self._alive.discard(pid)
            self._lost.append(pid)
            self._awaited.add(pid)
            self.barrier.set_live(self.barrier.live - {pid})
        self.stopping.gone(_LOG, f"agent {pid}", "agent %s lost: its nozzles are closed; the world goes on "
                           "without it", pid)  # fmt: skip

    def _on_control(self, _key: str, msg: RunControl) -> None:
        self._controls.put(msg)

    def _on_fault(self, _key: str, msg: Fault) -> None:
        self._faults.put(msg)

    def _apply_faults(self, tick: int) -> None:
        """Run-time faults (``swarm fault``, the dashboard): a window opens no earlier than tick ``tick + 1``
        (no sample already published changes). UWB dropouts and NLOS bursts go into the world's schedule
        (the truth carries them to the mothership's radios), a camera loss adds a window to the chaser's, a
        gyro step sets the vehicle's step (:mod:`swarm.core.faults`), a sensor delay holds samples back."""
        while True:
            try:
                f = self._faults.get_nowait()
            except queue.Empty:
                return
            now = (tick + 1) * self.sc.dt_s
            start = max(f.start_s if f.start_s is not None else now, now)
            refused = self._fault_refusal(f)
            if refused is not None:
                _LOG.warning("fault refused: %s: %s", f.kind, refused)
                data = {"kind": f.kind, "vehicle": f.vehicle, "reason": refused}
                self._world_event("fault_refused", tick * self.sc.dt_s, data)
                continue
            if f.kind in ("uwb_dropout", "nlos_burst"):
                who = list(self.ids)  # the whole radio network
            else:
                who = [f.vehicle] if f.vehicle is not None else list(self.chasers)
            if f.kind == "sensor_delay":
                for v in who:
                    self._delays.setdefault(v, []).append((start, start + f.duration_s, f.delay_s))
            else:
                value = {"nlos_burst": f.probability, "gyro_bias_step": f.rate_rad_s}.get(f.kind)
                self.world.add_fault(f.kind, start, f.duration_s, who, value)
            data = {"kind": f.kind, "start_s": start, "duration_s": f.duration_s, "vehicles": who}
            if f.kind == "nlos_burst":
                data["probability"] = f.probability
            self._world_event("fault", tick * self.sc.dt_s, data)
            _LOG.warning("fault applied: %s on %s from t = %.2f s", f.kind, who, start)

    def _fault_refusal(self, f: Fault) -> str | None:
        """Why the world cannot apply ``f`` (published as a ``fault_refused`` event), or None."""
        if f.vehicle is not None and f.vehicle not in self.world.index:
            why = f"vehicle: {f.vehicle!r} is not a vehicle of this scenario"
            self.drops.drop(self.keys.fault(), why)
            return why
        if f.kind == "camera_loss" and f.vehicle is not None and f.vehicle not in self.world.camera_loss:
            return f"vehicle: {f.vehicle!r} has no camera (only chasers do)"
        if f.kind == "sensor_delay" and self.clock.lockstep:
            return "needs a free-running clock (realtime or scaled:N): a lockstep world would wait on it"
        return None

    # ------------------------------------------------------------------------------ publishing

    def _declare(self) -> None:
        k = self.keys
        # one pair: each sample leaves at once (express); more: a tick's samples are a burst that Zenoh
        # batches into a few writes (docs/protocol.md, "QoS"; 32 vehicles: 2 ms of publishing -> 0.1 ms)
        ex = len(self.ids) <= 2
        self.pub_truth = {v: declare_reliable(self.session, k.truth(v), ex) for v in self.ids}
        self.pub_imu = {v: declare_reliable(self.session, k.imu(v), ex) for v in self.ids}
        self.pub_vision = {v: declare_reliable(self.session, k.vision(v), ex) for v in self.chasers}
        # for agent hosts every vehicle's imu and truth of a tick leave in one message each (docs/protocol.md,
        # "Rates"); declared either way: a checkpoint's tick, published again on resume, may hold a batch
        batches = {
            "imu_batch": k.world_imu(),
            "vision_batch": k.world_vision(),
            "truth_batch": k.world_truth(),
        }
        self._pubs = {  # by kind, then vehicle (a batch's is "", as world_sensors names it)
            "truth": self.pub_truth,
            "vision": self.pub_vision,
            "imu": self.pub_imu,
            **{kind: {"": declare_reliable(self.session, key, ex)} for kind, key in batches.items()},
        }
        # the per-vehicle truths for a viewer only (the mothership takes world/truth): Zenoh's matching
        # listeners keep who views which
        self._truth_matching = [
            pub.declare_matching_listener(lambda status, vid=vid: self._on_truth_matching(vid, status))
            for vid, pub in self.pub_truth.items()
        ]
        for vid, pub in self.pub_truth.items():
            if pub.matching_status.matching:
                self._viewed.add(vid)
        self.pub_event = {v: declare_reliable(self.session, k.event(v)) for v in self.chasers}
        self.pub_clock = declare_reliable(self.session, k.world_clock())
        self.pub_world_event = declare_reliable(self.session, k.world_event())
        if self.bundles:
            self.pub_bundle = {v: declare_reliable(self.session, k.bundle(v), ex) for v in self.ids}
            self.pub_bundle[""] = declare_reliable(self.session, k.world_bundle(), ex)

    def _on_truth_matching(self, vid: str, status) -> None:
        if status.matching:
            self._viewed.add(vid)
        else:
            self._viewed.discard(vid)

    def _publish_clock(self, k: int) -> None:
        self.pub_clock.put(encode(Clock(k, k * self.sc.dt_s, self.state, self.seed)))

    def _world_event(self, kind: str, t_s: float, data: dict) -> None:
        self.pub_world_event.put(encode(Event(t_s, kind, data)))

    def _encode_tick(self, k: int, frames) -> list[tuple[str, str, bytes]]:
        """The samples of tick ``k``, encoded, in publishing order
        (:func:`~swarm.transport.wire.world_sensors`): ``(kind, vehicle, payload)``."""
        t = k * self.sc.dt_s
        # a vehicle whose samples a sensor_delay window holds back keeps its own imu key (held in _send)
        solo = {v for v in self._delays if self._delay_s(v, t) is not None}
        return world_sensors(self.world, self.ids, self.chasers, k, frames, self._truth_every, self.batch,
                             solo, set(self._viewed))  # fmt: skip

    def _truths_between_ticks(self) -> bool:
        """Whether a tick's truths wait until halfway to the next tick (:meth:`_pace_to`): in a free-running
        world of agents a process each. Such an agent never waits for a range (it fuses one that comes after
        its tick before its next), so the mothership's wake and its ranges need not fall on the instant
        when the agents take their ``imu``; one pair's sensor-to-estimate p99 -23 % (BENCHMARKS.md, "The
        truths between the ticks"). A lockstep agent waits for its range: the truths lead the tick there.
        Agent hosts were not measured so and keep them first."""
        return not self.clock.lockstep and not self.batch

    def _pub(self, kind: str, vid: str):
        return self._pubs[kind][vid]

    def _publish_tick(self, k: int, sensors: list[tuple[str, str, bytes]]) -> None:
        """Publish tick ``k``'s samples (:meth:`_encode_tick`); imu and vision through :meth:`_send`. With
        bundles, into the pending bundles instead (a viewer's per-vehicle truth at once), sent once an agent
        is due at ``k`` or they hold the longest control period's ticks (:meth:`_flush_bundles`)."""
        t = k * self.sc.dt_s
        if self.bundles:
            for kind, vid, payload in sensors:
                receiver = _BUNDLED.get(kind)
                if receiver is None:  # a viewer's truth
                    self._pub(kind, vid).put(payload)
                else:
                    self._bundle.setdefault(vid, []).append((receiver, payload, k))
            self._bundle_ticks += 1
            if self.barrier.due(k) or self._bundle_ticks >= self._bundle_max:
                self._flush_bundles()
            return
        between = self._truths_between_ticks()
        for kind, vid, payload in sensors:
            if kind in ("imu", "vision"):
                self._send(vid, t, kind, payload)
            elif between:  # the truths (no batches without hosts), sent by _pace_to
                self._between.append((self._pub(kind, vid), payload))
            else:  # truths, and the batches (whose vehicles have no delay window: _encode_tick)
                self._pub(kind, vid).put(payload)
        self._release()

    def _flush_bundles(self, checkpoint_first: bool = True) -> None:
        """Send the pending bundles, one per receiver (more if they exceed a message), after the checkpoint
        of the current tick: no sample leaves before the checkpoint of its tick or a later one (at the end
        of the run none: the world's state is then past its last tick)."""
        if not self._bundle_ticks:
            return
        if checkpoint_first:
            self._checkpoint()
        for vid, entries in self._bundle.items():
            for payload in pack_bundle(entries):
                self.pub_bundle[vid].put(payload)
        self._bundle.clear()
        self._bundle_ticks = 0

    def _send(self, vid: str, t: float, kind: str, payload: bytes) -> None:
        """Publish now, or (a ``sensor_delay`` fault window) hold for a random delay: samples leave late and
        out of order."""
        delay = self._delay_s(vid, t)
        if delay is None:
            self._pub(kind, vid).put(payload)
            return
        wall = self._delay_rng.uniform(0.0, delay) / self.clock.factor
        heapq.heappush(self._held, (time.monotonic() + wall, next(self._held_seq), kind, vid, payload))

    def _delay_s(self, vid: str, t: float) -> float | None:
        """The delay bound [s] of the first ``sensor_delay`` window of vehicle ``vid`` open at time ``t``,
        ``None`` outside every window (its samples then leave at once)."""
        return next((delay for a, b, delay in self._delays.get(vid, ()) if a <= t < b), None)

    def _pace_to(self, tick: int, due: float) -> None:
        """A paced world (free-running, or a paced lockstep), tick ``tick``'s samples out: wait until
        ``due`` (``time.monotonic()``), when the next tick is, publishing on the way, halfway to ``due``, the
        tick's truths held back (:meth:`_truths_between_ticks`) and the clock if it is due.

        The clock goes out halfway, not with the samples: every subscriber wakes for it (the agents, the
        mothership, the launcher), and with the samples it fell on the vehicles' busiest tick (the camera's,
        a range's, the control's). One pair's sensor-to-estimate p99 fell by 15 % (BENCHMARKS.md, "The
        clock between the ticks"); the truths, the same way, by 23 % more. A world behind its schedule
        publishes them at once."""
        if tick % self.clock_every == 0 or self._between:
            self._wait_until(due - 0.5 * self.sc.dt_s / self.pace.factor)
            for pub, payload in self._between:
                pub.put(payload)
            self._between.clear()
            if tick % self.clock_every == 0:
                self._publish_clock(tick)
        self._wait_until(due)

    def _wait_until(self, t: float) -> None:
        """Sleep until ``time.monotonic()`` reaches ``t`` (or a stop)."""
        left = t - time.monotonic()
        if left > 0:
            self.stop.wait(left)

    def _release(self) -> None:
        now = time.monotonic()
        while self._held and self._held[0][0] <= now:
            _, _, kind, vid, payload = heapq.heappop(self._held)
            self._pub(kind, vid).put(payload)

    # ------------------------------------------------------------------------------ the run

    def _wait_for_start(self) -> bool:
        """Until every agent of the scenario and the mothership are alive; False on stop or timeout."""
        deadline = time.monotonic() + self.start_timeout_s
        while not self.stop.is_set():
            with self._lock:
                missing = [v for v in self.ids if v not in self._alive]
                ready = not missing and self._mothership
            if ready:
                return True
            if time.monotonic() > deadline:
                who = missing + ([] if self._mothership else ["mothership"])
                _LOG.error("not started: after %.0f s still no %s", self.start_timeout_s, ", ".join(who))
                return False
            time.sleep(0.005)
        return False

    def _announce_resume(self, k: int) -> None:
        """A resumed world's first words: ``world_resumed`` and its clock, then tick ``k``'s samples again."""
        t = k * self.sc.dt_s
        data = {"tick": k, "t_s": t, "seed": self.seed, "clock": str(self.clock), "state": self.state,
                "scenario": self.sc.name}  # fmt: skip
        self._world_event("world_resumed", t, data)
        self._publish_clock(k)
        # the earlier ticks first, in tick order: an agent takes its ticks in order, and the mothership its
        # UWB slots (each drops what it has already: stale or duplicate)
        ticks = [(j, pickle.loads(blob)) for j, blob, _ in self._earlier] + [(k, self._sensors)]
        for _, sensors in ticks:
            for kind, vid, payload in sensors:
                self._pub(kind, vid).put(payload)
        _LOG.warning("resumed from %s at tick %d (t = %.2f s): %d samples of ticks %d-%d published again",
                     self.ckpt_path, k, t, sum(len(s) for _, s in ticks), ticks[0][0], k)  # fmt: skip

    def _apply(self, k: int, commands: dict[str, Command]) -> None:
        """Tick ``k``'s commands into the world step (which opens the mode-triggered fault windows)."""
        for vid, cmd in commands.items():
            self.modes[vid] = cmd.mode
        self.world.take_commands(k, {vid: (cmd.actuators, cmd.mode) for vid, cmd in commands.items()})

    def _take_commands(self, k: int) -> bool:
        """Apply the commands of tick ``k``; False if a stop or an end-of-run control came first."""
        if not self.clock.lockstep:
            for sub in self._queued:
                sub.drain()
            with self._lock:
                latest, self._latest = self._latest, {}
            self._count_late(k, latest)
            self._apply(k, latest)
            return True
        deadline = time.monotonic() + self.step_timeout_s
        while not self.barrier.poll(k, 0.05):
            if self.stop.is_set() or self._handle_controls() or self.state == "paused":
                if self.stop.is_set() or self.state == "stopped":
                    return False
                deadline = time.monotonic() + self.step_timeout_s  # paused: the timeout starts again
                continue
            if time.monotonic() > deadline:
                break
        commands, missing = self.barrier.wait(k, 0)
        for vid in commands:
            self._missed_in_a_row.pop(vid, None)
        if missing:
            for vid in missing:
                self._missed_in_a_row[vid] = self._missed_in_a_row.get(vid, 0) + 1
            # a live agent that sends no command is not flying its vehicle: its actuators go idle (nozzles
            # closed, wheels stopped) until its next command, as for a lost one; holding its last command
            # would keep a thrust on for as long as the agent is stuck (PX4's offboard-loss failsafe)
            self.missing_ticks += 1
            _LOG.warning(
                "tick %d: no command from %s after %.1f s; their actuators idle until one comes",
                k, missing, self.step_timeout_s,
            )  # fmt: skip
            in_a_row = {vid: self._missed_in_a_row[vid] for vid in missing}  # (the launcher's hung agents)
            self._world_event("agent_missing", k * self.sc.dt_s, {"tick": k, "agents": missing,
                                                                  "in_a_row": in_a_row})  # fmt: skip
            for vid in missing:
                self._idle(vid)
        self._apply(k, commands)
        return True

    def _count_late(self, k: int, latest: dict[str, Command]) -> None:
        """Free-running: of the vehicles still flying whose agent has sent a command, count those that step
        tick ``k`` with an out-of-date command: the command of their last control tick ``<= k`` has not
        come (it is late: the world holds the one before). And on their control ticks, the commands due
        and those not in by the tick. These are the late ticks and late commands of ``swarm bench swarm``,
        judged where they matter, with no probe on the wire."""
        last = self._last_command_tick
        for vid, cmd in latest.items():
            last[vid] = max(cmd.tick, last.get(vid, -1))
        self._commanding.update(latest)
        flying = self._commanding - self.done
        self.commanded_ticks += len(flying)
        every, first = self.barrier.every, self.barrier.phase  # each agent's command period and phase [ticks]
        for vid in flying:
            phase = (k - first[vid]) % every[vid]
            stale = last[vid] < k - phase
            self.late_commands += stale
            if phase == 0:
                self.due_commands += 1
                self.late_due_commands += stale

    def _await_lost(self) -> None:
        """Lockstep: while an agent is lost (its token gone, not back yet), do not step: simulated time
        stands still while the launcher restarts it, as it does before the run starts (at most
        ``start_timeout_s``, then the run goes on without it, logged). Its vehicle's nozzles are closed."""
        if not self.clock.lockstep:
            return
        with self._lock:  # the agents handed the previous tick: the world waits for their commands now
            joining, self._joining = self._joining, []
            if joining:
                self.barrier.set_live(self.barrier.live | set(joining))
            waiting = bool(self._awaited or self._returned)
        if waiting:  # the other agents go on up to the current tick meanwhile
            self._flush_bundles()
        deadline = time.monotonic() + self.start_timeout_s
        while not self.stop.is_set():
            self._hand_tick_to_returned()
            with self._lock:
                awaited = sorted(self._awaited)
            if not awaited:
                return
            if time.monotonic() > deadline:
                _LOG.warning(
                    "agents %s not back after %.0f s: going on without them", awaited, self.start_timeout_s
                )
                with self._lock:
                    self._awaited.clear()
                return
            time.sleep(0.005)

    def _hand_tick_to_returned(self) -> None:
        """Lockstep: an agent whose token came back (restarted, subscribed) gets the current tick's samples
        of its vehicle again (a rejoining agent starts at the tick after the first imu it sees) and the
        world waits for its commands from the next tick on (:meth:`_await_lost`). Without this, a swarm
        whose every agent was lost at once (an agent host with all the vehicles) had nobody pacing the
        world when they came back: it stepped on at full speed, and the agents never caught up."""
        with self._lock:
            returned, self._returned = self._returned, []
            self._joining.extend(returned)
        for vid in returned:
            samples = [(kind, payload) for kind, v, payload in self._sensors if v == vid and kind != "truth"]
            # and its rows of the tick's batches, on its own keys: to it alone
            samples += batch_samples(self._sensors, vid)
            for kind, payload in samples:
                self._pub(kind, vid).put(payload)
            _LOG.info("agent %s back: in the lockstep from the next tick (%d samples of this one sent again)",
                      vid, len(samples))  # fmt: skip

    def _handle_controls(self) -> bool:
        """Apply pending run controls; True if any arrived."""
        got = False
        while True:
            try:
                msg = self._controls.get_nowait()
            except queue.Empty:
                return got
            got = True
            if msg.command == "pause" and self.state == "running":
                self.state = "paused"
            elif msg.command == "resume" and self.state == "paused":
                self.state = "running"
            elif msg.command in NEW_RUN_COMMANDS:
                self.end_reason = msg.command
                self.next_seed = msg.seed
                self.state = "stopped"
            _LOG.info("run control %s: clock %s", msg.command, self.state)
            if self.state != "stopped":
                self._checkpoint()  # a restart resumes paused if it was paused
            self._publish_clock(self.world.k)

    @property
    def done(self) -> set[str]:
        """The chasers whose run is over (contact)."""
        return {c for c, d in zip(self.referee.chasers, self.referee.done, strict=True) if d}

    def _referee(self, k: int) -> None:
        t = k * self.sc.dt_s
        keepouts, contacts = self.referee.judge(self.world.X, t, self.modes)
        for cid, range_m in keepouts:
            self.pub_event[cid].put(keepout_event(t, self.modes[cid], range_m))
        for cid, ct in contacts:
            self.world.attach(cid, self.sc.vehicles[cid].target)
            self.pub_event[cid].put(contact_event(t, self.modes[cid], ct))
            _LOG.info("%s: %s at t = %.2f s", cid, "contact" if ct.docked else "collision", t)

    def _close_lost(self) -> None:
        with self._lock:
            lost, self._lost = self._lost, []
        for vid in lost:
            self._idle(vid)
            self.modes[vid] = "HOLD"

    def _idle(self, vid: str) -> None:
        """The vehicle's actuators off from now on (nozzles closed, wheels stopped)."""
        self.world.set_command(vid, np.zeros(self.world.command_size(vid)))

    def run(self) -> dict:
        """Serve one run; returns the ``run_end`` data once stopped (a world whose run ended stays up,
        its clock ``stopped``, until a stop signal: the dashboard keeps showing the final state)."""
        k = self.keys
        warm_up(self.sc, self.seed)  # compiled (or loaded) before this process says it is ready
        self.world.reserve_noise(1)  # and the first tick's noise drawn (the same samples as at its step)
        self._declare()
        commands = ((k.agent_all("command"), Command, self._on_command),
                    (k.agent_all("commands"), CommandBatch, self._on_command_batch))  # fmt: skip
        if self.clock.lockstep:  # the barrier waits on each command as it comes
            for key, cls, handler in commands:
                subscribe_decoded(self.session, key, cls, handler, self.drops)
        else:
            # free-running, the world takes the newest command of each vehicle at its tick: the commands
            # wait in Zenoh's queue until then instead of waking a Python thread each (32 vehicles a
            # process each: world CPU -7 %, BENCHMARKS.md, "Queued inputs")
            self._queued = [
                QueuedSubscriber(self.session, key, cls, handler, self.drops, capacity=COMMAND_QUEUE)
                for key, cls, handler in commands
            ]
        subscribe_decoded(self.session, k.run_control(), RunControl, self._on_control, self.drops)
        subscribe_decoded(self.session, k.fault(), Fault, self._on_fault, self.drops)
        watch_liveliness(self.session, k, self._on_alive)
        if self.resumed_at is None:
            self._wall0, self._cpu0 = time.perf_counter(), time.process_time()
            self._checkpoint()  # tick 0, before the world shows up: one lost at any time can be resumed
        self._token = declare_liveliness(self.session, k, "world", self.process_id)
        from swarm.transport.process import print_ready

        print_ready("world", self.process_id)
        self.end_reason, self.next_seed = "stopped", None
        if not self._wait_for_start():
            state, self.state = self.state, "stopped"
            self._publish_clock(self.world.k)
            self.state = state  # a resumed world that gave up leaves its checkpoint as it was
            return {"reason": "not_started"}
        dt = self.sc.dt_s
        max_k = round(self.sc.sim.max_duration_s / dt)
        self._wall0 = wall0 = time.perf_counter()
        self._cpu0 = cpu0 = time.process_time()
        tick = self.world.k
        if self.resumed_at is None:
            start = {"seed": self.seed, "vehicles": self.ids, "clock": str(self.clock),
                     "scenario": self.sc.name}  # fmt: skip
            if self.clock.lockstep and self.pace is not None:
                start["pace"] = str(self.pace)
            self._world_event("run_start", 0.0, start)
            self._publish_clock(0)
        else:
            self._announce_resume(tick)
        pace0, pace_k = time.monotonic(), tick
        while True:
            if self.stop.is_set():
                self.end_reason = "stopped"
                break
            self._handle_controls()
            if self.state == "stopped":
                break
            if self.state == "paused":
                self._flush_bundles()
                time.sleep(0.01)
                pace0, pace_k = time.monotonic(), tick
                continue
            self._await_lost()
            if not self._take_commands(tick):
                break
            self._close_lost()
            self._apply_faults(tick)
            self._referee(tick)
            if len(self.done) == len(self.chasers):
                self.end_reason = "all_contact"
                break
            if tick >= max_k:
                # tick max_k's commands act over its step, as in the in-process run (whose loop, compiled or
                # not, steps every tick it processes): the effort of a run that ends here is the same
                self.world.step()
                self.end_reason = "max_duration"
                break
            frames = self.world.step()
            tick += 1
            self._new_tick(tick, frames)
            if not self.bundles:  # (bundles: at each flush, before any of their samples leaves)
                self._checkpoint()  # before any sample of the tick leaves: a restart resumes at this tick
            self._publish_tick(tick, self._sensors)
            if self.pace is not None:  # free-running, or a paced lockstep (never ahead of the wall clock)
                self._pace_to(tick, pace0 + (tick - pace_k) * dt / self.pace.factor)
            elif tick % self.clock_every == 0:  # an unpaced lockstep world: no idle time in its ticks
                self._publish_clock(tick)
        self._flush_bundles(checkpoint_first=False)  # the ticks up to the last: the agents process them
        wall = self._wall_before + time.perf_counter() - wall0
        cpu = self._cpu_before + time.process_time() - cpu0
        self.state = "stopped"
        t_end = tick * dt
        end = {
            "reason": self.end_reason, "tick": tick, "t_s": t_end, "seed": self.seed, "wall_s": wall,
            "realtime_factor": t_end / wall if wall > 0 else None, "cpu_s": cpu,
            "effort": self.world.effort_by_vehicle, "done": sorted(self.done),
            "closest_approach_m": {c: self.referee.closest_approach(c) for c in self.chasers},
            "missing_ticks": self.missing_ticks,
            "late_commands": None if self.clock.lockstep else [self.late_commands, self.commanded_ticks],
            "late_control_commands": None if self.clock.lockstep else [self.late_due_commands,
                                                                       self.due_commands],
            "next_seed": self.next_seed,
            "dropped": self.drops.total, "resumed_at": self.resumed_at,
            "checkpoint_us": 1e6 * self.ckpt_s / self.ckpt_n if self.ckpt_n else None,
        }  # fmt: skip
        self._world_event("run_end", t_end, end)
        self._publish_clock(tick)
        _LOG.info("run ended (%s) at t = %.2f s after %.2f s wall", self.end_reason, t_end, wall)
        if self.ckpt_n:
            _LOG.info("checkpoints: %d written, %.0f us each on average, %d bytes", self.ckpt_n,
                      1e6 * self.ckpt_s / self.ckpt_n, self.ckpt_bytes)  # fmt: skip
        self.drops.flush()
        wait_for_stop(self.stop)  # (in steps: a signal's handler must get to run, swarm.transport.stopping)
        if self._ckpt_file is not None:
            self._ckpt_file.close()
        return end


_BUNDLED = {"imu": "Imu", "vision": "Vision", "truth_batch": "TruthBatch"}
"""The samples a bundling world sends in bundles, by their kind in ``world_sensors``: the message type of the
entry (the receiver: the vehicle's agent, and ``""`` for the mothership's truth batches)."""


def unconfirmed_ticks(sc: Scenario) -> int:
    """How many ticks before its current one a lockstep world keeps the samples of, for a restart: those
    some process may not have received (a world killed loses what its Zenoh session had not sent yet, and
    an agent that lacks a tick's sample waits for it forever).

    At tick ``m`` the world has every live agent's command of its last control tick ``c <= m - 1`` (it
    waited for it), so that agent has processed every tick up to ``c >= m - every``: what it may lack lies
    in the ticks ``m - every + 1 .. m - 1`` (``every``: its control period). The mothership's truths are
    confirmed by the ranges those agents waited for: every UWB slot tick up to their last exchange (slots
    are served in tick order), which on a TDMA channel may lie a frame and a UWB period before ``c``."""
    ticks = max(sc.control_every(v) for v in sc.vehicles)
    slots, prm = tdma_channel(sc)
    if (slots >= 0).any():
        ticks += math.ceil(prm[0] * prm[1] / sc.dt_s) + sc.every(sc.uwb.rate_hz)
    return ticks


def warm_up(sc: Scenario, seed: int = 0) -> None:
    """Run every compiled kernel of a world tick once on a scratch world (dynamics, sensors, the camera's
    visibility and feature model, the referee), so that numba's compilation or cache load happens before a
    world process says it is ready, not inside the run (nor in its timing). ``swarm compile`` calls it too."""
    w = World(sc, seed)
    w.step(build_frames=False)
    w.k = w.vision_every  # a camera tick: every chaser's visibility test runs
    w.frames()
    w.radio_env(0.0)
    ref = Referee(sc)
    X = w.X.copy()
    for c, t in ref.pairs:  # every chaser next to its target: the whole referee runs
        X[c, 0:3] = X[t, 0:3] + 0.5 * ref.g.keepout_radius_m
    ref.judge(X, 0.0, dict.fromkeys(sc.chasers, "APPROACH"))
    for c in range(len(ref.pairs)):  # and the contact's report (the docked pose's quaternion product)
        ref.contact(X, c, 0.0)
