"""A stand-in swarm for the dashboard's tests: one process that publishes, over real Zenoh, what the
world, the mothership and the agents of ``N`` chaser/target pairs would (truth, estimate, guidance with
Algorithm 1 decisions, vision, mode events, clock, anchors), honours RunControl and declares the
liveliness tokens of every role. Its motion is scripted (a straight approach with the paper's mode
sequence and MDP radii that move), not simulated: the dashboard only draws what it hears.

    python -m tests.dashboard.fake_swarm --listen tcp/127.0.0.1:7447 --namespace tpods --pairs 1

Prints ``fake swarm running <ids>`` once its publishers and tokens are declared, and ``control <command>``
for each RunControl it obeys. ``pause`` stops its clock (a ``paused`` Clock is published once), ``resume``
restarts it; ``reset`` and ``new_seed`` start the run again at tick 0 (``new_seed``: the requested seed,
else the next one). ``--garbage`` also publishes invalid payloads on every key, after the valid ones on
every other tick, so that a latest-value subscriber sees garbage half the time. ``--token-only ROLE/ID``
only holds one liveliness token (an "agent process" a test can kill). With one pair the vehicle ids are
the docking scenario's (``chaser``, ``target``); with more, ``chaser<i>`` and ``target<i>``
(:func:`scenario_toml` writes the matching scenario).
"""

from __future__ import annotations

import argparse
import math
import queue
import signal
import sys
import threading
import time

import msgpack
import numpy as np
import zenoh

from swarm.core.mdp import DECISION_KEYS
from swarm.transport.keys import AGENT_KINDS, Keys
from swarm.transport.messages import (
    Anchors,
    Clock,
    DropCounter,
    Estimate,
    Event,
    Guidance,
    RunControl,
    Truth,
    Vision,
    encode,
)
from swarm.transport.session import ZenohArgs, declare_liveliness, open_session, subscribe_decoded

ANCHORS_M = ((1.0, -0.2, 0.5), (1.0, 0.2, -0.5), (-1.0, 0.2, -0.5), (-1.0, -0.2, 0.5))
Q_TARGET = (-0.5, 0.5, -0.5, 0.5)  # the paper's target attitude (-90, 0, -90) deg, xyz extrinsic
R_T, R_D, R1_INIT, R2_INIT, R_DOCKED = 1.0, 0.1, 0.1, 0.3, 0.1
REORIENT_AT, ALIGN_AT, DOCK_AT = 0.7, 0.45, 0.25  # ranges [m] where the scripted MDP switches

GARBAGE: tuple[bytes, ...] = (
    b"\x00\xffnot msgpack at all",
    msgpack.packb({"v": 2, "type": "Nonsense", "tick": 1}),
    msgpack.packb({"v": 99, "type": "Truth"}),
    msgpack.packb([1, 2, 3]),
    msgpack.packb({"v": 2, "type": "Truth", "tick": -4, "t_s": float("nan")}),
)


def vehicle_ids(pairs: int) -> list[tuple[str, str]]:
    """``(chaser, target)`` ids of each pair."""
    if pairs == 1:
        return [("chaser", "target")]
    return [(f"chaser{i}", f"target{i}") for i in range(pairs)]


def scenario_toml(pairs: int) -> str:
    """A scenario file whose vehicles are the fake swarm's (``pairs`` pairs; other fields defaulted)."""
    out = []
    for i, (chaser, target) in enumerate(vehicle_ids(pairs)):
        t = target_position(i)
        c = t - np.array([1.0, 1.0, 1.0])
        out.append(f'[vehicles.{chaser}]\nrole = "chaser"\nposition_m = {c.tolist()}\n')
        out.append(f'euler_deg = [0.0, 0.0, 0.0]\ntarget = "{target}"\n\n')
        out.append(f'[vehicles.{target}]\nrole = "target"\nposition_m = {t.tolist()}\n')
        out.append("euler_deg = [-90.0, 0.0, -90.0]\n\n")
    return "".join(out)


def target_position(i: int) -> np.ndarray:
    """Target ``i`` on a 4 x 4 grid from the paper's (1, 2, 1) m."""
    return np.array([1.0 + 1.2 * (i % 4), 2.0 + 1.2 * (i // 4), 1.0])


class Pair:
    """Scripted kinematics and guidance of one chaser/target pair."""

    def __init__(self, index: int, chaser: str, target: str, speed_m_s: float) -> None:
        self.chaser, self.target = chaser, target
        self.p_target = target_position(index)
        start = self.p_target - np.array([1.0, 1.0, 1.0])
        self.r0 = float(np.linalg.norm(self.p_target - start))
        self.u = (self.p_target - start) / self.r0
        self.speed = speed_m_s
        self.phase = 0.7 * index
        self.reset()

    def reset(self) -> None:
        self.mode = "APPROACH"
        self.r1, self.r2 = R1_INIT, R2_INIT
        self.decision: dict | None = None

    def range_at(self, t_s: float) -> float:
        return max(R_DOCKED, self.r0 - self.speed * t_s)

    def step(self, t_s: float) -> list[tuple[str, str, str, float]]:
        """Advance the guidance to time ``t_s``; returns the mode changes ``(from, to, reason, range)``."""
        r = self.range_at(t_s)
        changes = []

        def switch(to: str, reason: str) -> None:
            changes.append((self.mode, to, reason, r))
            self.mode = to

        if r <= R_T and self.mode in ("APPROACH", "REORIENT"):
            self.decision = self._decision(t_s, r)
        if self.mode == "APPROACH" and r <= REORIENT_AT:
            self.r2 = r
            switch("REORIENT", "A11 <= 0.4: reorient now")
        if self.mode == "REORIENT" and r <= ALIGN_AT:
            self.r1 = r
            switch("ALIGN", "pi2 <= 0.6: align now")
        if self.mode == "ALIGN" and r <= DOCK_AT:
            switch("DOCK", "aligned in front of the docking face")
        if self.mode == "DOCK" and r <= R_DOCKED:
            switch("DOCKED", "contact")
        return changes

    def _decision(self, t_s: float, r: float) -> dict:
        d = {k: None for k in DECISION_KEYS}
        d.update(t_s=t_s, r_m=r, d=0.8, qe_vec_norm=0.3, sigma_pos_max_m=0.012, sigma_uwb_m=0.02, r_t_m=R_T)
        d.update(r_d_m=R_D, r1_m=self.r1, r2_m=self.r2)
        if r > self.r2:
            d["A11"] = min(1.0, r / R_T * 0.6)
        else:
            a22 = min(1.0, r / self.r2 * 0.8)
            a32 = min(1.0, max(0.0, (self.r2 - r) / (self.r2 - R_D)))
            d.update(A22=a22, A23=1.0 - a22, A32=a32, A33=1.0 - a32)
            s = (1.0 - a22) + a32
            d.update(pi1=a32 / s if s > 0 else 0.5, pi2=(1.0 - a22) / s if s > 0 else 0.5)
        return d

    def chaser_pose(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        p = self.p_target - self.u * self.range_at(t_s)
        yaw = 0.3 * math.sin(0.2 * t_s + self.phase)
        return p, np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


def _estimate(tick: int, t_s: float, p: np.ndarray, q: np.ndarray, wobble: float) -> Estimate:
    decay = math.exp(-t_s / 20.0)
    err = 0.01 * decay * np.array([math.sin(t_s + wobble), math.cos(1.3 * t_s), math.sin(0.7 * t_s)])
    s = 0.004 + 0.02 * decay
    cov = np.diag([s**2, (0.6 * s) ** 2, (0.4 * s) ** 2, 1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4])
    cov[0, 1] = cov[1, 0] = 0.3 * s * 0.6 * s
    sigma = float(np.sqrt(np.max(np.linalg.eigvalsh(cov[:3, :3]))))
    counts = {"range_accepted": tick // 2, "range_rejected": tick // 100}
    return Estimate(
        tick=tick, t_s=t_s, p_nav=p + err, v_nav=np.zeros(3), q_nav_body=q, cov=cov, sigma_pos_max_m=sigma,
        mahalanobis_d=0.8, rejection_fraction=0.02, counts=counts,
    )  # fmt: skip


def tick_messages(keys: Keys, pairs: list[Pair], k: int, t: float) -> list[tuple[str, bytes]]:
    """What every pair publishes at tick ``k`` (time ``t`` [s]), in order, as ``(key, payload)``: mode events,
    truth and estimate of both vehicles, guidance, and every 5th tick a camera frame (the clock is the
    caller's). Advances each pair's scripted guidance to ``t``."""
    out: list[tuple[str, bytes]] = []
    for i, pair in enumerate(pairs):
        for frm, to, reason, r in pair.step(t):
            data = {"from": frm, "to": to, "t_s": t, "range_m": r, "reason": reason}
            out.append((keys.event(pair.chaser), encode(Event(t_s=t, kind="mode", data=data))))
            if to == "DOCKED":
                out.append((keys.event(pair.chaser), encode(Event(t_s=t, kind="contact", data={}))))
        p_c, q_c = pair.chaser_pose(t)
        for vid, p, q in ((pair.chaser, p_c, q_c), (pair.target, pair.p_target, np.array(Q_TARGET))):
            truth = Truth(tick=k, t_s=t, p_nav=p, v_nav=np.zeros(3), q_nav_body=q, w_body=np.zeros(3))
            out.append((keys.truth(vid), encode(truth)))
            out.append((keys.estimate(vid), encode(_estimate(k, t, p, q, float(i)))))
        r = pair.range_at(t)
        guidance = Guidance(
            tick=k, t_s=t, mode=pair.mode, range_m=r, r1_m=pair.r1, r2_m=pair.r2, r_t_m=R_T,
            decision=pair.decision, reason=f"{pair.mode} at r = {r:.3f} m",
        )  # fmt: skip
        out.append((keys.guidance(pair.chaser), encode(guidance)))
        out.append((keys.guidance(pair.target), encode(Guidance(tick=k, t_s=t, mode="STATION"))))
        if k % 5 == 0 and pair.mode in ("REORIENT", "ALIGN", "DOCK"):
            feats = np.array([[0.01 * j, 0.0, r] for j in range(6)])
            vision = Vision(
                tick=k, t_s=t, target_id=pair.target, face="+x", kind="features", data=feats,
                marker_ids=tuple(range(6)),
            )  # fmt: skip
            out.append((keys.vision(pair.chaser), encode(vision)))
    return out


class FakeSwarm:
    def __init__(self, session: zenoh.Session, keys: Keys, args: argparse.Namespace) -> None:
        self.session = session
        self.keys = keys
        self.args = args
        self.pairs = [Pair(i, c, t, args.speed) for i, (c, t) in enumerate(vehicle_ids(args.pairs))]
        self.seed = args.seed
        self.tick = 0
        self.paused = False
        self.controls: queue.Queue[RunControl] = queue.Queue()
        self._pubs: dict[str, zenoh.Publisher] = {}
        self.anchors = encode(Anchors(anchor_ids=(0, 1, 2, 3), positions_nav=np.array(ANCHORS_M)))
        self.drops = DropCounter()
        subscribe_decoded(
            session, keys.run_control(), RunControl, lambda _k, m: self.controls.put(m), self.drops
        )
        self._queryable = session.declare_queryable(keys.anchors(), self._on_query)
        skip = set(args.skip_token)
        self.tokens = [declare_liveliness(session, keys, "world", "world")]
        self.tokens.append(declare_liveliness(session, keys, "mothership", "mothership"))
        for pair in self.pairs:
            for vid in (pair.chaser, pair.target):
                if vid not in skip:
                    self.tokens.append(declare_liveliness(session, keys, "agent", vid))

    def _on_query(self, query: zenoh.Query) -> None:
        query.reply(self.keys.anchors(), self.anchors)

    def put(self, key: str, payload: bytes) -> None:
        pub = self._pubs.get(key)
        if pub is None:
            pub = self._pubs[key] = self.session.declare_publisher(
                key, reliability=zenoh.Reliability.RELIABLE, congestion_control=zenoh.CongestionControl.BLOCK
            )
        pub.put(payload)

    def clock(self, state: str) -> None:
        clock = Clock(tick=self.tick, t_s=self.tick * self.args.dt, state=state, seed=self.seed)
        self.put(self.keys.world_clock(), encode(clock))

    def handle_controls(self) -> None:
        while True:
            try:
                msg = self.controls.get_nowait()
            except queue.Empty:
                return
            print(f"control {msg.command}", flush=True)
            if msg.command == "pause":
                self.paused = True
                self.clock("paused")
            elif msg.command == "resume":
                self.paused = False
                self.clock("running")
            else:
                self.seed = msg.seed if msg.seed is not None else self.seed + (msg.command == "new_seed")
                self.restart()

    def restart(self) -> None:
        self.tick = 0
        for pair in self.pairs:
            pair.reset()
        self.clock("paused" if self.paused else "running")

    def step(self) -> None:
        """Publish tick ``self.tick`` of every pair, then advance the clock."""
        for key, payload in tick_messages(self.keys, self.pairs, self.tick, self.tick * self.args.dt):
            self.put(key, payload)
        self.clock("running")
        if self.args.garbage and self.tick % 2 == 1:
            self.garbage()
        self.tick += 1

    def garbage(self) -> None:
        bad = GARBAGE[self.tick % len(GARBAGE)]
        for pair in self.pairs:
            for vid in (pair.chaser, pair.target):
                for kind in AGENT_KINDS:
                    self.put(getattr(self.keys, kind)(vid), bad)
        self.put(self.keys.world_clock(), bad)
        self.put(self.keys.anchors(), bad)
        self.put(self.keys.run_control(), bad)  # the world's own subscriber drops it too

    def run(self, stop: threading.Event) -> None:
        self.put(self.keys.anchors(), self.anchors)
        self.clock("running")
        period = 1.0 / self.args.rate_hz
        next_t = time.monotonic()
        while not stop.is_set():
            self.handle_controls()
            if self.paused:
                stop.wait(0.01)
                next_t = time.monotonic()
                continue
            self.step()
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                stop.wait(delay)
            elif delay < -0.5:  # far behind (a loaded machine): do not try to catch up in a burst
                next_t = time.monotonic()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="fake_swarm", description=__doc__.split("\n\n")[0])
    p.add_argument("--listen", action="append", default=[])
    p.add_argument("--connect", action="append", default=[])
    p.add_argument("--namespace", default="tpods")
    p.add_argument("--pairs", type=int, default=1)
    p.add_argument("--rate-hz", type=float, default=200.0, help="ticks per wall-clock second")
    p.add_argument("--dt", type=float, default=0.01, help="seconds of swarm time per tick")
    p.add_argument("--speed", type=float, default=0.05, help="approach speed [m/s of swarm time]")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--garbage", action="store_true")
    p.add_argument("--skip-token", action="append", default=[], metavar="ID", help="no agent token for ID")
    p.add_argument("--token-only", default=None, metavar="ROLE/ID", help="only hold this liveliness token")
    args = p.parse_args(argv)
    keys = Keys(args.namespace)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    zargs = ZenohArgs(connect=tuple(args.connect), listen=tuple(args.listen))
    with open_session(zargs) as session:
        if args.token_only is not None:
            role, _, pid = args.token_only.partition("/")
            token = declare_liveliness(session, keys, role, pid)
            print(f"token {args.token_only}", flush=True)
            stop.wait()
            token.undeclare()
            return 0
        swarm = FakeSwarm(session, keys, args)
        ids = " ".join(v for pair in swarm.pairs for v in (pair.chaser, pair.target))
        print(f"fake swarm running {ids}", flush=True)
        swarm.run(stop)
    return 0


if __name__ == "__main__":
    sys.exit(main())
