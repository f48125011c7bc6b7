"""`swarm bench sim` runs and writes the fields BENCHMARKS.md quotes (no timing assertion)."""

from __future__ import annotations

import json
import math

from swarm.cli.main import main


def test_bench_sim_quick_writes_realtime_factors(tmp_path, capsys):
    out = tmp_path / "sim.json"
    assert main(["bench", "sim", "--quick", "--json", str(out)]) == 0
    rec = json.loads(out.read_text())
    assert rec["target_realtime_factor"] == 500.0
    assert set(rec["kinds"]) == {"cubesat", "ground"}  # every kind, side by side in one run
    for kind, k in rec["kinds"].items():
        for policy in ("fixed", "mdp"):
            case = k["cases"][policy]
            assert math.isfinite(case["realtime_factor_median"]) and case["realtime_factor_median"] > 0
            assert case["sim_time_s"][0] > 25.0, kind  # a whole docking was simulated, not a stub
            assert case["us_per_tick_median"] > 0
        assert k["realtime_factor"] == min(c["realtime_factor_median"] for c in k["cases"].values())
    assert rec["realtime_factor"] == min(k["realtime_factor"] for k in rec["kinds"].values())
    text = capsys.readouterr().out
    assert "goal: one docking >= 500x real time for every kind" in text
    assert "ground" in text and "cubesat" in text
    landing = rec["landing"]
    for policy in ("fixed", "mdp"):
        assert landing["cases"][policy]["realtime_factor_median"] > 0
        assert landing["cases"][policy]["sim_time_s"] > 10.0  # a whole landing
    frame = landing["rendered_frame_ms"]
    assert all(frame[k] > 0 for k in ("render", "detect", "pnp"))
    assert frame["total"] == frame["render"] + frame["detect"] + frame["pnp"]
    assert landing["corner_frame_us"] > 0 and landing["corner_frames_solved"] == landing["corner_frames"] > 0
    assert (
        "UAV landing" in text and "rendered camera, per 640 x 480 frame" in text and "corner camera" in text
    )
    missions = rec["missions"]
    assert rec["mission_target_realtime_factor"] == 1000.0
    assert {m["mission"] for m in missions.values()} == {"docking", "landing"}  # through the registry
    assert "landing-moving" in missions  # the third mission's scenario, a moving pad
    for name, m in missions.items():
        assert m["realtime_factor"] == min(c["realtime_factor_median"] for c in m["cases"].values()) > 0
        assert all(c["sim_time_s"] > 10.0 for c in m["cases"].values()), name  # whole runs
    assert "goal: every mission >= 1000x" in text
