"""``swarm launch landing --set sensors.profile=real-crazyflie`` equals ``swarm sim landing`` with the same
profile, bit for bit: the landing world process draws the range errors and the IMU vibration of real
flights (swarm.core.range_errors) from the streams the in-process world draws them from, and every process
reads the profile into the same scenario. One lockstep launch, real processes over real Zenoh on loopback."""

from __future__ import annotations

import json
import sys

import pytest

from swarm.landing_scenario import load_landing
from swarm.sim.landing import run_landing_fleet
from tests.transport.procs import Procs, free_port, loopback

SEED = 3
OVERRIDES = ["sensors.profile=real-crazyflie"]


@pytest.mark.slow  # a launched landing: ~30-60 s of wall time here; tests/core/test_range_errors.py runs
# the same kernels compiled against tick by tick by default
def test_a_launched_landing_with_real_sensor_errors_equals_swarm_sim(tmp_path):
    from agents.landing import warm_up
    from swarm.config import parse_override

    sc = load_landing("landing", dict(parse_override(o) for o in OVERRIDES))
    assert sc.uwb.multipath_sigma_m > 0 and sc.imu.vibration_accel_m_s2 > 0  # the profile is in
    warm_up(sc, 0, 0, sc.policy)
    out, ns = tmp_path / "run.json", f"rerr-{free_port()}"
    args = [sys.executable, "-m", "swarm.cli.main", "launch", "landing", "--headless", "--until-docked",
            "--seed", str(SEED), "--namespace", ns, "--listen", loopback(free_port()), "--json", str(out),
            "--timeout", "400"]  # fmt: skip
    for o in OVERRIDES:
        args += ["--set", o]
    with Procs() as procs:
        proc = procs.start(args)
        code = proc.wait(400.0)
        text = proc.output()
    assert code == 0, text
    got = json.loads(out.read_text())
    want = run_landing_fleet(sc, seed=SEED, record_series=False)
    for uid, w in want["uavs"].items():
        g = got["uavs"][uid]
        for key in ("landed", "landing_error_m", "energy_j", "landing_time_s", "final_mode", "retries",
                    "pad_frames", "deviation_distance_m", "sim_time_s"):  # fmt: skip
            assert g[key] == w[key], (uid, key, g[key], w[key])
        assert g["modes"] == w["modes"], uid
