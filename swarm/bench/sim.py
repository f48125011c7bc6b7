"""``swarm bench sim``: speed of one in-process docking of each vehicle kind (BENCHMARKS.md; issue
12's target: >= 500x real time on one core for both kinds).

For each kind (:data:`BENCH_SCENARIOS`: the paper's cube docking, and the ground docking from a start that
flies every mode), one run per policy and seed after a warm-up run (numba compilation and caches
excluded), on one core: simulated seconds per wall second (the real-time factor) and wall time per 10 ms
tick, side by side in one run of the bench; and where the time goes (cProfile, top functions by own time)
for the cube's first policy.
"""

from __future__ import annotations

import cProfile
import io
import os
import pstats
import time

TARGET_RTF = 500.0
MISSION_TARGET_RTF = 1000.0
"""Issue 44's target: one in-process run of every mission >= 1000x real time."""

MISSION_SCENARIOS = ("docking", "ground-docking", "landing", "landing-moving")
"""One bundled scenario of each mission (and of the docking's second kind), in :func:`_missions`."""

BENCH_SCENARIOS = {
    "cubesat": ("docking", {}),
    "ground": ("ground-docking", {"vehicles.chaser.position_m": [0.4, 0.3, 0.05],
                                  "vehicles.chaser.euler_deg": [0.0, 0.0, 90.0]}),
}  # fmt: skip
"""Kind -> (scenario, overrides) of its benchmark docking."""


def _cases(sc, seeds) -> dict:
    from swarm.sim.docking import run_docking

    cases = {}
    for policy in ("fixed", "mdp"):
        walls, sims = [], []
        for seed in seeds:
            t0 = time.perf_counter()
            res = run_docking(sc, policy, seed, record_series=False)
            walls.append(time.perf_counter() - t0)
            sims.append(res["sim_time_s"])
        rtf = sorted(s / w for s, w in zip(sims, walls, strict=True))
        ticks = [s / sc.dt_s for s in sims]
        cases[policy] = {
            "realtime_factor_median": rtf[len(rtf) // 2],
            "realtime_factor_min": rtf[0],
            "wall_s": walls,
            "sim_time_s": sims,
            "us_per_tick_median": sorted(w / t * 1e6 for w, t in zip(walls, ticks, strict=True))[
                len(ticks) // 2
            ],
        }
    return cases


def _landing(quick: bool) -> dict:
    """One landing per policy and seed in the corner mode (real-time factor), the rendered mode's cost per
    camera frame: render, detect, PnP (medians over frames along a descent), and the corner mode's: the
    compiled projection with noise and pose solve (swarm.core._pad_nb, _pnp_nb) on the same frames."""
    import numpy as np

    from swarm.core import rotations as rot
    from swarm.core._pad_nb import camera_vector, corner_frame_nb, pack_frame_nb
    from swarm.core._pnp_nb import solve_pose_nb
    from swarm.core.pad_vision import Renderer, detect, estimate_pose, make_detector
    from swarm.sim.landing import load_landing, run_landing

    sc = load_landing("landing")
    run_landing(sc, "fixed", 0, record_series=False)  # warm-up
    cases = {}
    for policy in ("fixed", "mdp"):
        rtf = []
        for seed in (0,) if quick else (0, 1, 2):
            r = run_landing(sc, policy, seed, record_series=False)
            rtf.append(r["sim_time_s"] / r["wall_s"])
        cases[policy] = {"realtime_factor_median": sorted(rtf)[len(rtf) // 2], "sim_time_s": r["sim_time_s"]}
    board, cam = sc.pad.board, sc.camera.intrinsics
    renderer, detector = Renderer(board, cam), make_detector(board)
    rng = np.random.default_rng(0)
    q_cam_pad = rot.quat_conj(np.array([1.0, 0.0, 0.0, 0.0]))
    ms: dict[str, list[float]] = {"render": [], "detect": [], "pnp": []}
    bc, cv, m = np.ascontiguousarray(board.corners), camera_vector(cam), len(board.corners)
    Z, idx, px = rng.standard_normal(8 * m), np.zeros(m, dtype=np.int64), np.zeros((m, 4, 2))
    obj, img2, var = np.zeros((4 * m, 3)), np.zeros((4 * m, 2)), np.zeros(4 * m)
    t_o, R_o, cov_o = np.zeros(3), np.zeros((3, 3)), np.zeros((6, 6))
    R_cam_pad = rot.quat_to_matrix(q_cam_pad)
    corner_us: list[float] = []
    solved = 0
    for h in np.linspace(0.5, 6.0, 12 if quick else 48):
        t_cam = np.array([0.05, -0.03, h])
        t0 = time.perf_counter()
        img = renderer.render(t_cam, q_cam_pad, rng)
        t1 = time.perf_counter()
        ids, corners = detect(img, board, detector)
        t2 = time.perf_counter()
        estimate_pose(ids, corners, board, cam)
        t3 = time.perf_counter()
        ms["render"].append((t1 - t0) * 1e3)
        ms["detect"].append((t2 - t1) * 1e3)
        ms["pnp"].append((t3 - t2) * 1e3)
        for _ in range(2):  # the first call of the first frame loads the kernels
            t4 = time.perf_counter()
            k, _pos = corner_frame_nb(bc, R_cam_pad, t_cam, cv, Z, 0, idx, px)
            n = pack_frame_nb(bc, idx, px, k, cv, obj, img2, var)
            ok = n > 0 and solve_pose_nb(obj, img2, var, n, cv, t_o, R_o, cov_o)
            t5 = time.perf_counter()
        corner_us.append((t5 - t4) * 1e6)
        solved += bool(ok)
    frame = {k: float(np.median(v)) for k, v in ms.items()}
    frame["total"] = sum(frame.values())
    return {"scenario": sc.name, "camera_mode": "corners", "cases": cases,
            "realtime_factor": min(c["realtime_factor_median"] for c in cases.values()),
            "rendered_frame_ms": frame, "corner_frame_us": float(np.median(corner_us)),
            "corner_frames": len(corner_us), "corner_frames_solved": solved,
            "image_px": [cam.width_px, cam.height_px]}  # fmt: skip


def _missions(quick: bool, measured: dict[str, dict]) -> dict:
    """Each of :data:`MISSION_SCENARIOS` through its mission's in-process runner (``swarm sim``'s, by the
    registry): real-time factor per policy, median over the seeds, after a warm-up run. A scenario in
    ``measured`` (name -> its cases, run above with the same runner and seeds) is not run again."""
    from swarm.missions import mission_of

    out = {}
    for name in MISSION_SCENARIOS:
        mission = mission_of(name)
        cases = {p: {"realtime_factor_median": c["realtime_factor_median"], "sim_time_s": c["sim_time_s"]}
                 for p, c in measured.get(name, {}).items()}  # fmt: skip
        if not cases:
            sc = mission.load(name)
            mission.run_one(sc, "fixed", 0)  # warm-up: compilation, caches
            for policy in ("fixed", "mdp"):
                rtf, sim = [], 0.0
                for seed in (0,) if quick else (0, 1, 2):
                    t0 = time.perf_counter()
                    r = mission.run_one(sc, policy, seed)
                    wall = time.perf_counter() - t0
                    sim = float(r["sim_time_s"])
                    rtf.append(sim / wall)
                cases[policy] = {"realtime_factor_median": sorted(rtf)[len(rtf) // 2], "sim_time_s": sim}
        out[name] = {
            "mission": mission.name,
            "cases": cases,
            "realtime_factor": min(c["realtime_factor_median"] for c in cases.values()),
        }
    return out


def run(quick: bool = False) -> dict:
    from swarm.scenario import load_scenario
    from swarm.sim.docking import run_docking

    scenarios = {k: load_scenario(name, ov) for k, (name, ov) in BENCH_SCENARIOS.items()}
    for sc in scenarios.values():
        run_docking(sc, "fixed", 0, record_series=False)  # warm-up: compilation, caches
    seeds = (0,) if quick else (0, 1, 2)
    kinds = {k: {"scenario": sc.name, "cases": _cases(sc, seeds)} for k, sc in scenarios.items()}
    for rec in kinds.values():
        rec["realtime_factor"] = min(c["realtime_factor_median"] for c in rec["cases"].values())
        rec["us_per_tick"] = max(c["us_per_tick_median"] for c in rec["cases"].values())
    prof = cProfile.Profile()
    prof.enable()
    run_docking(scenarios["cubesat"], "fixed", 0, record_series=False)
    prof.disable()
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(12)
    landing = _landing(quick)
    cube = {p: {**c, "sim_time_s": c["sim_time_s"][0]} for p, c in kinds["cubesat"]["cases"].items()}
    # the bundled docking is the cube's case above, the landing the UAV landing's: not run twice
    measured = {BENCH_SCENARIOS["cubesat"][0]: cube, landing["scenario"]: landing["cases"]}
    return {
        "realtime_factor": min(k["realtime_factor"] for k in kinds.values()),
        "target_realtime_factor": TARGET_RTF,
        "kinds": kinds,
        "cases": kinds["cubesat"]["cases"],  # the cube's, as before kinds
        "load_avg_1m": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
        "profile_top": buf.getvalue(),
        "landing": landing,
        "mission_target_realtime_factor": MISSION_TARGET_RTF,
        "missions": _missions(quick, measured),
    }


def format_report(rec: dict) -> str:
    lines = ["In-process docking of each vehicle kind (one core), after a warm-up run", ""]
    lines.append(
        f"{'kind':<8} {'policy':<8} {'real-time factor (median, min)':>32} {'us per 10 ms tick':>18} "
        f"{'sim s':>8}"
    )
    for kind, k in rec["kinds"].items():
        for policy, c in k["cases"].items():
            rtf = f"{c['realtime_factor_median']:>22.0f}x ({c['realtime_factor_min']:.0f}x)"
            lines.append(
                f"{kind:<8} {policy:<8} {rtf} {c['us_per_tick_median']:>18.1f} {c['sim_time_s'][0]:>8.1f}"
            )
    met = rec["realtime_factor"] >= rec["target_realtime_factor"]
    lines.append("")
    lines.append(
        f"goal: one docking >= {rec['target_realtime_factor']:.0f}x real time for every kind: "
        f"{'met' if met else 'NOT met'} ({rec['realtime_factor']:.0f}x, the slowest kind)"
    )
    lnd = rec["landing"]
    lines.append("")
    lines.append(f"UAV landing ({lnd['scenario']}, corner-projection camera, the compiled landing tick):")
    for policy, c in lnd["cases"].items():
        lines.append(
            f"  {policy:<8} {c['realtime_factor_median']:>6.0f}x real time "
            f"({c['sim_time_s']:.1f} s simulated)"
        )
    met_l = lnd["realtime_factor"] >= rec["target_realtime_factor"]
    lines.append(
        f"  goal: one landing >= {rec['target_realtime_factor']:.0f}x: {'met' if met_l else 'NOT met'}"
    )
    f = lnd["rendered_frame_ms"]
    w, h = lnd["image_px"]
    lines.append(
        f"  rendered camera, per {w} x {h} frame: render {f['render']:.1f} ms, detect {f['detect']:.1f} ms, "
        f"PnP {f['pnp']:.2f} ms, total {f['total']:.1f} ms"
    )
    lines.append(
        f"  corner camera, per frame (compiled projection, noise, PnP): {lnd['corner_frame_us']:.0f} us"
    )
    lines.append("")
    lines.append("Every mission, in-process (swarm sim's runner), real-time factor (median over seeds):")
    for name, m in rec["missions"].items():
        per = ", ".join(f"{p} {c['realtime_factor_median']:.0f}x" for p, c in m["cases"].items())
        lines.append(f"  {name:<16} {m['mission']:<8} {per}")
    slowest = min(m["realtime_factor"] for m in rec["missions"].values())
    met_m = slowest >= rec["mission_target_realtime_factor"]
    lines.append(
        f"  goal: every mission >= {rec['mission_target_realtime_factor']:.0f}x: "
        f"{'met' if met_m else 'NOT met'} ({slowest:.0f}x, the slowest)"
    )
    lines.append(f"machine: 1-min load {rec['load_avg_1m']}")
    lines.append("")
    lines.append("profile of one run (cProfile inflates Python-heavy code), top functions by own time:")
    lines.extend("  " + ln for ln in rec["profile_top"].splitlines() if ln.strip() and "/" in ln)
    return "\n".join(lines)
