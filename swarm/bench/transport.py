"""``swarm bench transport``: the swarm over Zenoh on this machine (BENCHMARKS.md).

Three measurements in one run, all between separate processes on loopback, in the launcher's two
topologies (``swarm launch --topology``): a ``star`` of Zenoh clients of one router, so each message crosses
the router, and a ``mesh`` of peers linked directly, one hop a message (the launcher's default, ``auto``,
for a swarm of a few processes, one pair's among them):

1. raw Zenoh ping-pong round trip of a 64-byte payload between two client processes through a router (the
   star's floor) and between two peers linked directly (the mesh's floor), and the
   echoing process's CPU per message received and published again, from Zenoh's callback thread and
   handed to a main thread as the swarm's processes do (the per-message floor of a Python process); and
   the CPU of one ``put`` (and, for scale, of numpy's sum of 1000 floats) back to back and after the
   thread slept :data:`IDLE_S`, as a swarm process does between ticks: a woken thread finds its caches
   (on a VM, its whole vCPU) cold, and that, not the code, is most of a 100 Hz process's cost per message;
2. the lockstep tick period of ``swarm launch docking --agents N`` for N = 1, 4, 16 pairs (the default
   topology: a mesh of one pair, a star of more), and of one pair in a star: wall time per world tick
   over a fixed simulated span (``run_end``'s ``wall_s`` / ticks), and the real-time factor; each
   topology's one-pair tick is set against its own floor;
3. sensor-to-estimate latency in ``realtime`` mode (a mesh): the chaser's ``estimate(k)``'s publication
   minus its ``imu(k)``'s, from the publishers' own Zenoh timestamps (the probe of ``swarm bench swarm``,
   :class:`~swarm.bench.swarm.LatencyProbe`): the hop from the world to the agent plus the agent's receive,
   filter and publish time; beside it, to the estimate's arrival at the probe (``delivered``).

``--cpu-latency US`` holds the CPU wake-up latency request of ``swarm launch --cpu-latency``
(:mod:`swarm.cpu_latency`) for the whole bench: every figure then shows what the swarm gets with it.

Run as ``python -m swarm.bench.transport ping|pong ...`` it is the ping or the pong process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from swarm import cpu_latency
from swarm.bench.swarm import LatencyProbe, timestamping_args
from swarm.cli.children import member_args
from swarm.transport.session import ZenohArgs, free_loopback_endpoint, open_session

IDLE_S = 0.01
"""The sleep before each "after idle" sample of the wake cost: a tick of the 100 Hz swarm."""
WAKE_SAMPLES = 200
"""Samples of each wake-cost figure (the first tenth dropped: warm-up)."""

QUICK = {"rtt_samples": 500, "pairs": (1, 4), "span_s": 5.0, "latency_s": 4.0}
FULL = {"rtt_samples": 3000, "pairs": (1, 4, 16), "span_s": 10.0, "latency_s": 10.0}


def _member(endpoint: str, topology: str):
    """A session that joins as a launched child of ``topology`` (:func:`swarm.cli.children.member_args`)."""
    return open_session(member_args(endpoint, topology))


def _await_link(s, topology: str, what: str) -> None:
    """In a mesh, wait until ``s`` has its direct link to the other peer (until then the router brokers
    their messages: a round trip through it is not the mesh's)."""
    deadline = time.monotonic() + 10
    while topology == "mesh" and not list(s.info.peers_zid()):
        if time.monotonic() > deadline:
            raise RuntimeError(f"{what}: no direct link to the other peer within 10 s")
        time.sleep(0.005)


def _router(endpoint: str):
    # configured as the launcher's router (lean Zenoh runtime), so that the RTT is the floor of its ticks
    return open_session(ZenohArgs(mode="router", listen=(endpoint,)), lean=True)


def _pong(endpoint: str, ns: str, style: str = "direct", topology: str = "star") -> None:
    """Echo every ping. ``direct``: published from Zenoh's callback thread; ``handoff``: the callback hands
    the message to the main thread through a condition, which publishes it: the pattern of the swarm's
    processes (a callback only queues, the main loop steps and publishes). On stdin's end it prints its CPU
    time per echo [us] (every thread of the process, Zenoh's own included) over the pings it answered."""
    import zenoh

    first, n = [None], [0]
    with _member(endpoint, topology) as s:
        pub = s.declare_publisher(f"{ns}/pong", express=True, reliability=zenoh.Reliability.RELIABLE)
        cond, queue, eof = threading.Condition(), [], threading.Event()

        def on_ping(sample) -> None:
            if first[0] is None:
                first[0] = time.process_time()
            n[0] += 1
            if style == "direct":
                pub.put(sample.payload)
                return
            with cond:
                queue.append(sample.payload)
                cond.notify()

        s.declare_subscriber(f"{ns}/ping", on_ping)
        print("pong ready", flush=True)
        threading.Thread(target=lambda: (sys.stdin.read(), eof.set()), daemon=True).start()
        while not eof.is_set():  # the main loop (handoff) or a wait for stdin's end (direct)
            with cond:
                cond.wait_for(lambda: queue or eof.is_set(), 0.1)
                items, queue[:] = queue[:], []
            for payload in items:
                pub.put(payload)
        cpu = time.process_time() - first[0] if first[0] is not None else float("nan")
        print(json.dumps({"cpu_us_per_echo": 1e6 * cpu / max(n[0], 1), "echoes": n[0]}), flush=True)


def _ping(endpoint: str, ns: str, n: int, wake: bool = False, topology: str = "star") -> None:
    import zenoh

    got = threading.Event()
    with _member(endpoint, topology) as s:
        pub = s.declare_publisher(f"{ns}/ping", express=True, reliability=zenoh.Reliability.RELIABLE)
        s.declare_subscriber(f"{ns}/pong", lambda _s: got.set())
        deadline = time.monotonic() + 10  # until the router routes our pings to the pong's subscriber
        while not pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.005)
        _await_link(s, topology, "ping")
        payload = b"x" * 64
        rtts = []
        for i in range(n + 50):
            got.clear()
            t0 = time.perf_counter()
            pub.put(payload)
            if not got.wait(2.0):
                continue
            if i >= 50:  # warm-up
                rtts.append(time.perf_counter() - t0)
        print(json.dumps({"rtts": rtts, "wake": _wake_cost(pub, payload) if wake else None}), flush=True)


def _wake_cost(pub, payload: bytes) -> dict:
    """This thread's CPU [us, median] for one ``pub.put(payload)`` and for numpy's sum of 1000 floats, back to
    back (``warm``) and each after a sleep of :data:`IDLE_S` (``idle``)."""
    x = np.zeros(1000)
    out = {}
    for name, op in (("put", lambda: pub.put(payload)), ("numpy_sum", x.sum)):
        for how, pause in (("warm", 0.0), ("idle", IDLE_S)):
            cpu = []
            for _ in range(WAKE_SAMPLES):
                if pause:
                    time.sleep(pause)
                c0 = time.thread_time()
                op()
                cpu.append(time.thread_time() - c0)
            out[f"{name}_{how}_us"] = 1e6 * float(np.median(cpu[WAKE_SAMPLES // 10 :]))
    return out


def _rtt(n: int, style: str = "direct", wake: bool = False, topology: str = "star") -> dict:
    """Ping-pong between two processes of ``topology`` (:func:`_member`: clients through a router, or two
    peers linked directly): the round trip [us] and the pong's CPU per echo [us] (:func:`_pong`'s
    ``style``); with ``wake``, the pinging process's :func:`_wake_cost` too."""
    endpoint, ns = free_loopback_endpoint(), f"bench{os.getpid()}"
    with _router(endpoint):
        pong_cmd = [sys.executable, "-m", "swarm.bench.transport", "pong", endpoint, ns, style, topology]
        pong = subprocess.Popen(pong_cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        try:
            assert pong.stdout.readline().strip() == "pong ready"
            ping = [sys.executable, "-m", "swarm.bench.transport", "ping", endpoint, ns, str(n), topology,
                    *(["wake"] if wake else [])]  # fmt: skip
            out = subprocess.run(ping, capture_output=True, text=True, timeout=300)
            got = json.loads(out.stdout.strip().splitlines()[-1])
            rtts = np.array(got["rtts"]) * 1e6
        finally:
            pong.stdin.close()
            echo = json.loads(pong.stdout.readline() or "{}")
            pong.wait(10)
    return {"median": float(np.median(rtts)), "p99": float(np.percentile(rtts, 99)), "n": len(rtts),
            "pong_cpu_us_per_echo": echo.get("cpu_us_per_echo"), "wake_cost_us": got["wake"]}  # fmt: skip


def _lockstep(pairs: int, span_s: float, topology: str = "auto") -> dict:
    from swarm.cli.children import resolved, swarm_processes

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        cmd = [sys.executable, "-m", "swarm.cli.main", "launch", "docking", "--headless", "--until-docked",
               "--agents", str(pairs), "--set", f"sim.max_duration_s={span_s}", "--json", str(out),
               "--namespace", f"bench{os.getpid()}x{pairs}", "--topology", topology]  # fmt: skip
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
        if not out.exists():
            raise RuntimeError(
                f"launch --agents {pairs} --topology {topology} failed ({r.returncode}):\n{r.stderr[-2000:]}"
            )
        res = json.loads(out.read_text())
    ticks = round(res["sim_time_s"] * 100)
    cpu = res.get("cpu_s", {})
    agents = [v for k, v in cpu.items() if k != "world" and v is not None]
    return {
        "topology": resolved(topology, swarm_processes(2 * pairs)),
        "tick_us": 1e6 * res["wall_s"] / ticks, "realtime_factor": res["realtime_factor"], "ticks": ticks,
        "world_cpu_us_per_tick": 1e6 * cpu["world"] / ticks if cpu.get("world") is not None else None,
        "agent_cpu_us_per_tick": 1e6 * float(np.mean(agents)) / ticks if agents else None,
    }  # fmt: skip


def _latency(duration_s: float, topology: str = "mesh") -> dict:
    """One pair free-running (``topology``: the launcher's default for one pair, a mesh)."""
    from swarm.transport.keys import Keys

    ns = f"benchlat{os.getpid()}"
    keys = Keys(ns)
    endpoint = free_loopback_endpoint()
    cmd = [sys.executable, "-m", "swarm.cli.main", "launch", "docking", "--headless", "--clock", "realtime",
           "--namespace", ns, "--listen", endpoint, "--topology", topology]  # fmt: skip
    probe = LatencyProbe()
    with tempfile.TemporaryDirectory() as tmp:
        cmd += timestamping_args(tmp)  # every process stamps what it publishes
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        try:
            for line in proc.stdout:
                if line.startswith("swarm up:"):
                    break
            with _member(endpoint, topology) as s:  # (in a mesh, linked to the world and the chaser directly)
                s.declare_subscriber(keys.estimate("chaser"), probe.on_estimate)
                time.sleep(duration_s)
        finally:
            proc.send_signal(2)
            proc.wait(30)
    with probe.lock:
        pairs = zip(probe.latency, probe.delivered, strict=True)
        ticks = sorted((k, lat, dlv) for (_, k, lat), (_, _, dlv) in pairs)
    a = np.array([lat for _, lat, _ in ticks[10:]]) * 1e6  # (the first ten: the run's start)
    d = np.array([dlv for _, _, dlv in ticks[10:]]) * 1e6
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "n": len(a),
            "delivered_median": float(np.median(d)), "delivered_p99": float(np.percentile(d, 99)),
            "unstamped": probe.unstamped, "without_imu_stamp": probe.without_imu}  # fmt: skip


def run(preset: dict) -> dict:
    """Every measurement, with ``preset["cpu_latency"]`` (``--cpu-latency``; None: none) held throughout."""
    with cpu_latency.hold(preset.get("cpu_latency")) as held:
        return {**_run(preset), **held.as_dict()}


def _run(preset: dict) -> dict:
    rtt = _rtt(preset["rtt_samples"], wake=True)
    mesh_rtt = _rtt(preset["rtt_samples"], topology="mesh")
    handoff = _rtt(preset["rtt_samples"], "handoff")
    lock = {str(n): _lockstep(n, preset["span_s"]) for n in preset["pairs"]}
    star = _lockstep(1, preset["span_s"], "star")
    latency = _latency(preset["latency_s"])
    one = lock["1"]["tick_us"]
    floor = mesh_rtt if lock["1"]["topology"] == "mesh" else rtt  # the path one pair's messages take
    return {
        "zenoh_rtt_us": rtt,
        "mesh_rtt_us": mesh_rtt,
        "handoff_rtt_us": handoff,
        "lockstep_tick_us": {n: v["tick_us"] for n, v in lock.items()},
        "lockstep_topology": {n: v["topology"] for n, v in lock.items()},
        "lockstep_realtime_factor": {n: v["realtime_factor"] for n, v in lock.items()},
        "lockstep_cpu_us_per_tick": {
            n: {"world": v["world_cpu_us_per_tick"], "agent_mean": v["agent_cpu_us_per_tick"]}
            for n, v in lock.items()
        },
        "star_one_pair": {
            "tick_us": star["tick_us"],
            "realtime_factor": star["realtime_factor"],
            "world_cpu_us_per_tick": star["world_cpu_us_per_tick"],
            "agent_cpu_us_per_tick": star["agent_cpu_us_per_tick"],
        },
        "latency_us": latency,
        # each topology's tick against the floor of the path its messages take
        "one_pair_tick_over_rtt": one / floor["median"],
        "star_one_pair_tick_over_rtt": star["tick_us"] / rtt["median"],
        "one_pair_tick_over_router_rtt": one / rtt["median"],
        "goals": {
            "one_pair_tick_le_2x_rtt": one <= 2 * floor["median"],
            "star_one_pair_tick_le_2x_rtt": star["tick_us"] <= 2 * rtt["median"],
            "pairs16_ge_10x_realtime": lock.get("16", {}).get("realtime_factor", 0) >= 10,
            "latency_p99_lt_1ms": latency["p99"] < 1000,
        },
        "cores": os.cpu_count(),
        "load_1min": os.getloadavg()[0],
        "cpu_idle": cpu_latency.idle_config(),  # the wake tax's cause (swarm.cpu_latency), while it was held
    }


def format_report(r: dict) -> str:
    rtt, mesh, hand = r["zenoh_rtt_us"], r["mesh_rtt_us"], r["handoff_rtt_us"]
    w = rtt["wake_cost_us"]
    lines = [] if r.get("cpu_latency_us") is None else [
        f"CPU wake-up latency request of {r['cpu_latency_us']} us (--cpu-latency): "
        + ("held throughout" if r.get("cpu_latency_held") else "NOT held: the kernel's idle states")
    ]  # fmt: skip
    if r.get("cpu_idle"):
        lines.append(cpu_latency.describe_idle(r["cpu_idle"]))
    lines += [
        f"Zenoh ping-pong RTT (64 B, two clients via the router): median {rtt['median']:.0f} us, "
        f"p99 {rtt['p99']:.0f} us",
        f"  two peers linked directly (a mesh): median {mesh['median']:.0f} us, p99 {mesh['p99']:.0f} us",
        f"  CPU per message received and sent again by the echoing process: "
        f"{rtt['pong_cpu_us_per_echo']:.0f} us from Zenoh's callback thread, "
        f"{hand['pong_cpu_us_per_echo']:.0f} us handed to a main thread as the swarm's processes do "
        f"(RTT median {hand['median']:.0f} us)",
        f"  CPU of one put: {w['put_warm_us']:.0f} us back to back, {w['put_idle_us']:.0f} us after "
        f"{IDLE_S * 1e3:.0f} ms idle (numpy's sum of 1000 floats: {w['numpy_sum_warm_us']:.1f} and "
        f"{w['numpy_sum_idle_us']:.1f} us): what a thread woken every tick pays on this machine",
        "lockstep tick period (swarm launch --agents N):",
    ]
    for n, t in r["lockstep_tick_us"].items():
        lines.append(
            f"  {n:>2} pair(s): {t:8.0f} us per tick, {r['lockstep_realtime_factor'][n]:.1f}x real time "
            f"({r['lockstep_topology'][n]})"
        )
    for n, c in r["lockstep_cpu_us_per_tick"].items():
        if c["world"] is not None and c["agent_mean"] is not None:
            lines.append(
                f"  {n:>2} pair(s): CPU per tick: world {c['world']:.0f} us, "
                f"each agent {c['agent_mean']:.0f} us"
            )
    st = r["star_one_pair"]
    lines.append(
        f"   1 pair,  star: {st['tick_us']:4.0f} us per tick, {st['realtime_factor']:.1f}x real time "
        f"(CPU per tick: world {st['world_cpu_us_per_tick']:.0f} us, "
        f"each agent {st['agent_cpu_us_per_tick']:.0f} us)"
    )
    lines.append(
        f"  one pair / RTT (goal <= 2): mesh {r['one_pair_tick_over_rtt']:.1f} (its tick over the peers' "
        f"RTT; "
        f"{r['one_pair_tick_over_router_rtt']:.1f} over the router's), star "
        f"{r['star_one_pair_tick_over_rtt']:.1f} (over the router's)"
    )
    lat = r["latency_us"]
    lines.append(
        f"sensor-to-estimate latency (realtime, imu published -> estimate published): median "
        f"{lat['median']:.0f} us, p99 {lat['p99']:.0f} us"
        + (f"; delivered to the probe: median {lat['delivered_median']:.0f} us, p99 "
           f"{lat['delivered_p99']:.0f} us" if "delivered_p99" in lat else "")
    )  # fmt: skip
    lines.append("goals: " + ", ".join(f"{k} {'met' if v else 'NOT met'}" for k, v in r["goals"].items()))
    return "\n".join(lines)


if __name__ == "__main__":
    if sys.argv[1] == "pong":
        _pong(sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5])
    elif sys.argv[1] == "ping":
        _ping(sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[6:7] == ["wake"], sys.argv[5])
