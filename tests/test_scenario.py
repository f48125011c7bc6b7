"""Tests of swarm.scenario: the bundled paper scenario, validation of every table, cross-field checks and
overrides. Bad files are the bundled ``docking.toml`` with one line changed, so each error comes
from an otherwise valid, complete scenario."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from swarm.config import dump_toml, to_mapping
from swarm.core.range_error_params import RangeErrorParams
from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing
from swarm.scenario import SCENARIO_DIR, Scenario, load_scenario

DOCKING_TOML = SCENARIO_DIR / "docking.toml"
TEXT = DOCKING_TOML.read_text()


def variant(tmp_path: Path, table: str, key: str, value: str) -> Path:
    """``docking.toml`` with ``key = value`` in ``[table]`` (``""`` = top level), replacing the existing
    line or appending one to the table; returns the new file."""
    lines = TEXT.splitlines()
    header = re.compile(r"^\s*\[([^\]]+)\]")
    current, start, end, hit = "", None, len(lines), None
    if table == "":
        start = 0
    for i, line in enumerate(lines):
        m = header.match(line)
        if m:
            if current == table and start is not None and i > start:
                end = i
                break
            current = m.group(1).strip()
            if current == table:
                start = i + 1
            continue
        if current == table and re.match(rf"^\s*{re.escape(key)}\s*=", line):
            hit = i
            end = i
            break
    assert start is not None, f"no table [{table}] in docking.toml"
    if hit is not None:
        lines[hit] = f"{key} = {value}"
    else:
        lines.insert(end, f"{key} = {value}")
    path = tmp_path / "variant.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def load_variant(tmp_path: Path, table: str, key: str, value: str) -> Scenario:
    return load_scenario(variant(tmp_path, table, key, value))


def mismatches(a, b, path: str = "", rel: float = 1e-4) -> list[str]:
    """Dotted paths where two ``to_mapping`` trees differ; floats compared to ``rel`` (the file writes derived
    constants such as 10 deg/h in deg/s to 5 significant figures)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}.{k}".lstrip(".") for k in set(a) ^ set(b)]
        for k in set(a) & set(b):
            out += mismatches(a[k], b[k], f"{path}.{k}".lstrip("."), rel)
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [path]
        return [
            m
            for i, (x, y) in enumerate(zip(a, b, strict=True))
            for m in mismatches(x, y, f"{path}[{i}]", rel)
        ]
    if isinstance(a, float) or isinstance(b, float):
        ok = (
            isinstance(a, int | float)
            and isinstance(b, int | float)
            and math.isclose(a, b, rel_tol=rel, abs_tol=1e-12)
        )
        return [] if ok else [f"{path}: {a!r} vs {b!r}"]
    return [] if a == b else [f"{path}: {a!r} vs {b!r}"]


# ---- the bundled scenario ---------------------------------------------------------------------------------


def test_docking_toml_matches_the_code_defaults():
    diff = mismatches(to_mapping(load_scenario("docking")), to_mapping(Scenario()))
    assert diff == []


def test_docking_toml_mdp_r_d_matches_the_code_default():
    assert load_scenario("docking").mdp.r_d_m == Scenario().mdp.r_d_m


def test_bundled_name_and_file_path_load_the_same_scenario():
    assert load_scenario("docking") == load_scenario(DOCKING_TOML) == load_scenario(str(DOCKING_TOML))


def test_target_quaternion_follows_the_stated_euler_convention():
    sc = load_scenario("docking")
    q = sc.q0("target")
    expected = np.array([-0.5, 0.5, -0.5, 0.5])
    assert np.allclose(q, expected, atol=1e-12) or np.allclose(q, -expected, atol=1e-12)
    # lowercase "xyz" is scipy's extrinsic convention about the fixed mothership axes
    scipy_q = Rotation.from_euler(sc.euler_seq, sc.vehicles["target"].euler_deg, degrees=True).as_quat()
    assert abs(float(np.dot(q, scipy_q))) == pytest.approx(1.0)


def test_chaser_starts_at_the_identity_attitude():
    np.testing.assert_allclose(load_scenario("docking").q0("chaser"), [0.0, 0.0, 0.0, 1.0], atol=1e-12)


def test_paper_numbers_are_in_the_docking_scenario():
    sc = load_scenario("docking")
    # paper sec. III: anchors and the tag position P1 = (0.05, 0.05, 0) m; 2 cm range noise
    assert sc.anchors_m == ((1.0, -0.2, 0.5), (1.0, 0.2, -0.5), (-1.0, 0.2, -0.5), (-1.0, -0.2, 0.5))
    assert sc.kind("chaser").mounts.tag_lever_arm_body_m == (0.05, 0.05, 0.0)
    assert sc.estimator_for("chaser").lever_arm_body_m == sc.kind("chaser").mounts.tag_lever_arm_body_m
    assert sc.uwb.sigma_m == 0.02
    assert sc.camera.feature_sigma_m == 0.001
    # paper Fig. 5: chaser at (0, 1, 0) m, (0, 0, 0) deg; target at (1, 2, 1) m, (-90, 0, -90) deg
    ch, tg = sc.vehicles["chaser"], sc.vehicles["target"]
    assert (ch.role, ch.position_m, ch.euler_deg, ch.target) == (
        "chaser",
        (0.0, 1.0, 0.0),
        (0.0, 0.0, 0.0),
        "target",
    )
    assert (tg.role, tg.position_m, tg.euler_deg) == ("target", (1.0, 2.0, 1.0), (-90.0, 0.0, -90.0))
    # paper sec. V-C fixed radii; Algorithm 1's initial radii and thresholds
    assert (sc.fixed.r2_m, sc.fixed.r1_m) == (0.8, 0.3)
    assert (sc.mdp.r1_init_m, sc.mdp.r2_init_m) == (0.1, 0.3)
    assert (sc.mdp.a11_threshold, sc.mdp.pi2_threshold) == (0.4, 0.6)
    # hardware rates (paper sec. VI-A): IMU 100 Hz, UWB 50 Hz, vision 20 Hz
    assert (sc.sim.imu_rate_hz, sc.uwb.rate_hz, sc.camera.rate_hz) == (100.0, 50.0, 20.0)
    assert sc.chasers == ["chaser"]


def test_scenario_round_trips_through_toml(tmp_path):
    path = tmp_path / "dumped.toml"
    path.write_text(dump_toml(load_scenario("docking")))
    assert load_scenario(path) == load_scenario("docking")


# ---- file-level errors ------------------------------------------------------------------------------------


def test_missing_file_names_the_file(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.toml"):
        load_scenario(tmp_path / "nope.toml")


def test_unknown_bundled_name_names_the_file_it_looked_for():
    with pytest.raises(ConfigError, match=r"no_such_scenario\.toml"):
        load_scenario("no_such_scenario")


def test_toml_syntax_error_names_the_file_and_line(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('name = "docking"\n[guidance\nkeepout_radius_m = 0.15\n')
    with pytest.raises(ConfigError, match=r"broken\.toml.*invalid TOML.*line 2"):
        load_scenario(path)


@pytest.mark.parametrize(
    ("table", "key", "field"),
    [
        ("guidance", "keepout_radius", "guidance.keepout_radius"),
        ("estimator", "sigma_rang_m", "estimator.sigma_rang_m"),
        ("vehicles.chaser", "mass_kg", "vehicles.chaser.mass_kg"),
        ("", "seed", "seed"),
    ],
)
def test_unknown_key_is_named(tmp_path, table, key, field):
    with pytest.raises(ConfigError, match=rf"{re.escape(field)}: unknown key"):
        load_variant(tmp_path, table, key, "1.0")


@pytest.mark.parametrize(
    ("table", "old", "value", "write"),
    [
        ("initial", "sigma_pos_m", "0.07", "initial.sigma_position_m = 0.07 instead"),
        ("initial", "sigma_att_deg", "3.0", "initial.sigma_attitude_deg = 3.0 instead"),
        # the unit changed with the name: the value to write is converted (0.0035 deg = 6.1087e-05 rad)
        ("gyro", "arw_deg_s_rthz", "0.0035", f"gyro.gyro_noise_rad_s_rthz = {0.0035 * math.pi / 180.0!r}"),
    ],
)
def test_a_renamed_key_names_the_key_and_value_to_write(tmp_path, table, old, value, write):
    with pytest.raises(ConfigError, match=rf"{re.escape(table + '.' + old)}: renamed; write") as exc:
        load_variant(tmp_path, table, old, value)
    assert write in str(exc.value) and "variant.toml" in str(exc.value)


def test_a_renamed_landing_imu_key_names_the_new_key(tmp_path):
    text = (SCENARIO_DIR / "landing.toml").read_text()
    assert "gyro_noise_rad_s_rthz = 0.001" in text
    path = tmp_path / "old-landing.toml"
    path.write_text(text.replace("gyro_noise_rad_s_rthz = 0.001", "gyro_noise = 0.001"))
    want = r"imu\.gyro_noise: renamed; write imu\.gyro_noise_rad_s_rthz = 0\.001"
    with pytest.raises(ConfigError, match=want):
        load_landing(path)


def test_unknown_key_suggests_the_close_one(tmp_path):
    with pytest.raises(ConfigError, match="did you mean 'keepout_radius_m'"):
        load_variant(tmp_path, "guidance", "keepout_radius", "0.15")


def test_unknown_table_is_named(tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text(TEXT + "\n[guidence]\nkeepout_radius_m = 0.15\n")
    with pytest.raises(ConfigError, match=r"guidence: unknown key"):
        load_scenario(path)


@pytest.mark.parametrize(
    ("table", "key", "value", "field"),
    [
        ("estimator", "sigma_range_m", '"big"', "estimator.sigma_range_m"),
        ("guidance", "max_retries", "1.5", "guidance.max_retries"),
        ("ahrs", "enabled", "1", "ahrs.enabled"),
        ("guidance", "docking_face", "1", "guidance.docking_face"),
        ("vehicles.chaser", "position_m", "[0.0, 1.0]", "vehicles.chaser.position_m"),
        ("vehicles.chaser", "position_m", '[0.0, "1", 0.0]', r"vehicles.chaser.position_m[1]"),
        ("camera", "width_px", "320.5", "camera.width_px"),
        ("uwb", "dropout_windows_s", "[[1.0]]", "uwb.dropout_windows_s[0]"),
        ("estimator", "structure", '"triple"', "estimator.structure"),
        ("", "policy", '"markov"', "policy"),
    ],
)
def test_wrong_type_is_named(tmp_path, table, key, value, field):
    with pytest.raises(ConfigError, match=re.escape(field) + ": expected"):
        load_variant(tmp_path, table, key, value)


@pytest.mark.parametrize(
    ("table", "key", "value", "field"),
    [
        ("estimator", "sigma_range_m", "-1.0", "estimator.sigma_range_m"),
        ("estimator", "gate_probability", "1.0", "estimator.gate_probability"),
        ("guidance", "align_distance_m", "0.16", "guidance.align_distance_m"),  # inside keep-out + margin
        ("guidance", "docking_face", '"+w"', "guidance.docking_face"),
        ("guidance", "resume_sigma_pos_m", "0.07", "guidance.resume_sigma_pos_m"),
        ("uwb", "nlos_probability", "1.5", "uwb.nlos_probability"),
        ("uwb", "sigma_m", "0.0", "uwb.sigma_m"),
        ("uwb", "nlos_max_m", "0.1", "uwb.nlos_max_m"),
        ("camera", "fx_px", "0.0", "camera.fx_px"),
        ("camera", "min_range_m", "2.0", "camera.min_range_m"),
        ("mdp", "a11_threshold", "1.5", "mdp.a11_threshold"),
        ("mdp", "r1_init_m", "0.5", "mdp.r1_init_m"),
        ("fixed", "r1_m", "0.9", "fixed.r1_m"),
        ("sim", "imu_rate_hz", "0.0", "sim.imu_rate_hz"),
        ("station", "deadband_m", "-0.01", "station.deadband_m"),
        ("initial", "sigma_position_m", "0.0", "initial.sigma_position_m"),
        ("agent", "health_window_s", "0.0", "agent.health_window_s"),
        ("vehicles.chaser", "role", '"pilot"', "vehicles.chaser.role"),
        ("", "euler_seq", '"xyw"', "euler_seq"),
    ],
)
def test_bad_value_is_named(tmp_path, table, key, value, field):
    with pytest.raises(ConfigError, match=re.escape(field)) as exc:
        load_variant(tmp_path, table, key, value)
    assert "variant.toml" in str(exc.value)  # and the file it came from


# ---- cross-field checks -----------------------------------------------------------------------------------


@pytest.mark.parametrize("target", ['"ghost"', '"chaser"'])  # missing; not a target
def test_chaser_target_must_be_a_target(tmp_path, target):
    with pytest.raises(ConfigError, match=r"vehicles\.chaser\.target"):
        load_variant(tmp_path, "vehicles.chaser", "target", target)


def test_chaser_without_target_is_an_error(tmp_path):
    path = tmp_path / "no_target.toml"
    path.write_text(TEXT.replace('target = "target"\n', ""))
    with pytest.raises(ConfigError, match=r"vehicles\.chaser\.target"):
        load_scenario(path)


@pytest.mark.parametrize(
    ("table", "value", "field"),
    [
        ("uwb", "30.0", "uwb.rate_hz"),
        ("camera", "7.0", "camera.rate_hz"),
        ("kinds.cubesat.translation_control", "3.0", "kinds.cubesat.translation_control.rate_hz"),
        ("ahrs", "40.0", "ahrs.rate_hz"),
        ("ahrs", "200.0", "ahrs.rate_hz"),  # faster than the tick
    ],
)
def test_rate_must_divide_the_imu_rate(tmp_path, table, value, field):
    with pytest.raises(ConfigError, match=rf"{re.escape(field)}.*sim\.imu_rate_hz"):
        load_variant(tmp_path, table, "rate_hz", value)


def test_rates_that_divide_the_imu_rate_are_accepted(tmp_path):
    assert load_variant(tmp_path, "uwb", "rate_hz", "25.0").uwb.rate_hz == 25.0


@pytest.mark.parametrize(
    ("key", "value", "mount"),
    [
        ("pos_body_m", "[0.0, 0.0, -0.04]", "kinds.cubesat.mounts.camera_pos_body_m"),
        ("q_body_cam", "[0.0, 1.0, 0.0, 0.0]", "kinds.cubesat.mounts.q_body_cam"),
    ],
)
def test_the_camera_mount_is_given_once_in_the_kinds_mounts(tmp_path, key, value, mount):
    """Where the camera sits is the kind's: a [camera] mount in a file of the current format is an error
    naming the kind's field (a file of the older format has its [camera] mount moved there, below)."""
    with pytest.raises(ConfigError, match=rf"camera\.{key}: where the camera sits is the vehicle kind's"):
        load_variant(tmp_path, "camera", key, value)


@pytest.mark.parametrize(
    ("key", "value"), [("lever_arm_body_m", "[0.0, 0.05, 0.0]"), ("camera_pos_body_m", "[0.0, 0.0, -0.04]")]
)
def test_the_filters_mount_model_is_the_kinds_mount(tmp_path, key, value):
    with pytest.raises(ConfigError, match=rf"estimator\.{key}: the filter's model of the mount is"):
        load_variant(tmp_path, "estimator", key, value)


def test_a_scenario_of_the_format_before_kinds_loads_with_a_warning_naming_the_moves(tmp_path):
    """A file written before vehicle kinds (top-level [dynamics], [thrusters], ..., the tag lever arm, the
    camera mount, the nozzle misalignment) is the same scenario, and a FutureWarning names each move."""
    old = TEXT
    for block in ("[kinds.cubesat.mounts]", "[kinds.cubesat.dispersions]"):  # the blocks that were not tables
        start = old.index(block)
        old = old[:start] + old[old.index("\n[", start + 1) + 1 :]
    for table in ("dynamics", "thrusters", "attitude_control", "translation_control"):
        old = old.replace(f"[kinds.cubesat.{table}]", f"[{table}]")
    old = old.replace('policy = "mdp"\n', 'policy = "mdp"\ntag_lever_arm_body_m = [0.05, 0.05, 0.0]\n')
    old = old.replace(
        'model = "features"',
        'pos_body_m = [0.0, 0.0, -0.05]\nq_body_cam = [1.0, 0.0, 0.0, 0.0]\nmodel = "features"',
    )
    old = re.sub(r"(\[estimator\][^\n]*\n)", r"\1lever_arm_body_m = [0.05, 0.05, 0.0]\n", old)
    old = old.replace('distribution = "normal"', 'distribution = "normal"\nthruster_misalignment_deg = 0.0')
    assert "[kinds." not in old
    path = tmp_path / "old.toml"
    path.write_text(old)
    with pytest.warns(FutureWarning, match="dynamics -> kinds.cubesat.dynamics") as rec:
        sc = load_scenario(path)
    text = str(rec[0].message)
    for moved in ("tag_lever_arm_body_m -> kinds.cubesat.mounts.tag_lever_arm_body_m",
                  "camera.pos_body_m -> kinds.cubesat.mounts.camera_pos_body_m",
                  "dispersions.thruster_misalignment_deg -> kinds.cubesat.dispersions.",
                  "estimator.lever_arm_body_m (dropped"):  # fmt: skip
        assert moved in text
    assert sc == load_scenario("docking")


def test_an_override_of_a_key_before_kinds_is_moved_with_a_warning():
    with pytest.warns(FutureWarning, match="--set dynamics.mass_kg: moved to kinds.cubesat.dynamics.mass_kg"):
        sc = load_scenario("docking", {"dynamics.mass_kg": 1.3})
    assert sc.kinds.cubesat.dynamics.mass_kg == 1.3


def test_a_vehicle_of_an_unknown_kind_is_named(tmp_path):
    with pytest.raises(
        ConfigError,
        match=r"vehicles\.chaser\.kind must be one of \['cubesat', 'ground', 'quadrotor'\], got 'boat'",
    ):
        load_variant(tmp_path, "vehicles.chaser", "kind", '"boat"')
    # the quadrotor is registered but the docking dispatch has no branch for it: refused naming the file,
    # the key and its line, the value and what is missing (not a crash in the compiled tick)
    with pytest.raises(ConfigError) as err:
        load_variant(tmp_path, "vehicles.chaser", "kind", '"quadrotor"')
    msg = str(err.value)
    assert msg.startswith(str(tmp_path)) and ".toml: vehicles.chaser.kind = 'quadrotor'" in msg, msg
    assert "swarm/kinds/_dispatch.py" in msg and "(at line " in msg, msg


def test_marker_cube_must_match_the_guidance_cube(tmp_path):
    with pytest.raises(ConfigError, match=r"markers\.half_size_m.*guidance\.half_size_m"):
        load_variant(tmp_path, "markers", "half_size_m", "0.04")


# ---- overrides --------------------------------------------------------------------------------------------


def test_overrides_apply_and_leave_the_rest_alone():
    sc = load_scenario(
        "docking",
        overrides={
            "uwb.nlos_probability": 0.1,
            "fixed.r2_m": 0.7,
            "vehicles.chaser.position_m": [0.0, 1.2, 0.0],
        },
    )
    assert sc.uwb.nlos_probability == 0.1
    assert sc.fixed.r2_m == 0.7
    assert sc.vehicles["chaser"].position_m == (0.0, 1.2, 0.0)
    base = load_scenario("docking")
    assert sc.uwb.sigma_m == base.uwb.sigma_m
    assert sc.vehicles["target"] == base.vehicles["target"]
    assert sc.estimator == base.estimator


def test_bad_override_names_the_field_and_says_it_was_an_override():
    with pytest.raises(ConfigError, match=r"estimator\.sigma_range_m.*override"):
        load_scenario("docking", overrides={"estimator.sigma_range_m": -1.0})


def test_override_of_an_unknown_key_is_named():
    with pytest.raises(ConfigError, match=r"guidance\.keepout_radius: unknown key"):
        load_scenario("docking", overrides={"guidance.keepout_radius": 0.2})


def test_override_can_break_a_cross_field_check():
    with pytest.raises(ConfigError, match=r"uwb\.rate_hz"):
        load_scenario("docking", overrides={"uwb.rate_hz": 30.0})


def test_thruster_cube_size_must_match_the_guidance_cube():
    with pytest.raises(ConfigError, match=r"kinds\.cubesat\.thrusters\.half_size_m must equal guidance"):
        load_scenario("docking", {"kinds.cubesat.thrusters.half_size_m": 0.06})


def test_with_pairs_copies_every_vehicle_on_a_grid_of_the_configured_spacing():
    import itertools

    from swarm.scenario import Scenario

    sc = Scenario()
    assert sc.with_pairs(1) is sc
    s4 = sc.with_pairs(4)
    assert set(s4.vehicles) == {f"{v}{i}" for v in ("chaser", "target") for i in range(4)}
    assert all(s4.vehicles[f"chaser{i}"].target == f"target{i}" for i in range(4))
    offsets = [
        np.subtract(s4.vehicles[f"chaser{i}"].position_m, sc.vehicles["chaser"].position_m) for i in range(4)
    ]
    for i in range(4):  # each copy moves chaser and target together: the pair's geometry is kept
        d = np.subtract(s4.vehicles[f"target{i}"].position_m, sc.vehicles["target"].position_m)
        assert np.allclose(d, offsets[i])
    gaps = sorted(np.linalg.norm(a - b) for a, b in itertools.combinations(offsets, 2))
    assert np.isclose(gaps[0], sc.swarm.pair_spacing_m)  # nearest neighbours one spacing apart
    assert np.allclose(np.mean(offsets, axis=0), 0.0)  # centred on the original pair
    with pytest.raises(ConfigError, match=r"--agents must be an integer in 1\.\.64, got 0"):
        sc.with_pairs(0)
    assert {s4.control_phase(v) for v in s4.vehicles} == {0}  # not staggered: every copy as the original


def test_staggered_copies_spread_their_control_ticks_and_an_agent_controls_on_its_own():
    """swarm.stagger_control: vehicle m of the copies controls first on tick m % 10 (docking's 10 Hz
    control at 100 Hz), so 16 vehicles put at most 2 control steps on any tick; an agent's decide() follows
    its phase. A phase at or beyond the period is refused, naming the field."""
    from swarm.step.agent import VehicleAgent

    sc = load_scenario("docking", {"swarm.stagger_control": True})
    s8 = sc.with_pairs(8)
    every = sc.control_every("chaser")
    phases = [s8.control_phase(v) for v in s8.vehicles]
    assert phases == [m % every for m in range(16)]
    per_tick = [sum((k - p) % every == 0 for p in phases) for k in range(every)]
    assert max(per_tick) == 2 and sum(per_tick) == 16
    x = np.array(s8.vehicles["target1"].position_m)
    a = VehicleAgent(s8, "target1", x, np.zeros(3), s8.q0("target1"), np.full(9, 1e-4), "mdp")
    assert s8.control_phase("target1") == 3
    assert [k for k in range(25) if a.decide(k, k * s8.dt_s) is not None] == [3, 13, 23]
    with pytest.raises(ConfigError, match=r"vehicles\.chaser\.control_phase must be below its control"):
        load_scenario("docking", {"vehicles.chaser.control_phase": every})
    with pytest.raises(ConfigError, match="control_phase must be an integer >= 0"):
        load_scenario("docking", {"vehicles.chaser.control_phase": -1})


def test_thrust_dispersions_with_the_nominal_acceleration_psd_warn():
    """A truth with mass or nozzle errors has an unmodelled acceleration ~200x the nominal filter's q
    (NEES.md, table 4: 8-18 % collisions): loading such a scenario says so, naming the fields; raising q
    (or no thrust dispersion) is silent."""
    import warnings as w

    from swarm.scenario import load_scenario

    with pytest.warns(UserWarning, match="estimator.accel_psd_m2_s3.*dispersions.mass_sigma_frac = 0.03"):
        load_scenario("docking", {"dispersions.mass_sigma_frac": 0.03})
    with w.catch_warnings():
        w.simplefilter("error")
        load_scenario("docking", {"dispersions.mass_sigma_frac": 0.03, "estimator.accel_psd_m2_s3": 1e-8})
        load_scenario("docking", {"dispersions.position_sigma_m": 0.03})


# --------------------------------------------------------------------- tables shared by every mission


def test_a_shared_table_is_one_dataclass_in_every_mission_with_its_own_defaults():
    docking, landing = load_scenario("docking"), load_landing("landing")
    assert type(docking.initial) is type(landing.initial)
    assert set(RangeErrorParams.__dataclass_fields__) <= set(type(docking.uwb).__dataclass_fields__)
    assert isinstance(docking.uwb, RangeErrorParams) and isinstance(landing.uwb, RangeErrorParams)
    # each mission keeps its defaults: a 2 deg MEKF start (paper) and a GNSS-class landing start
    assert (docking.initial.sigma_position_m, docking.initial.sigma_attitude_deg) == (0.05, 2.0)
    assert (landing.initial.sigma_position_m, landing.initial.sigma_attitude_deg) == (1.0, 1.0)


def test_a_landing_file_gets_the_shared_tables_refusals(tmp_path):
    text = (SCENARIO_DIR / "landing.toml").read_text()
    path = tmp_path / "old.toml"
    path.write_text(text.replace("[initial]\n", "[initial]\nsigma_att_deg = 3.0\n"))
    with pytest.raises(ConfigError, match=r"initial\.sigma_attitude_deg = 3\.0 instead"):
        load_landing(path)
    path.write_text(text.replace("[initial]\n", "[initial]\nsigma_velocity_m_s = 0.0\n"))
    with pytest.raises(ConfigError, match=r"initial\.sigma_velocity_m_s must be a positive number"):
        load_landing(path)
    path.write_text(text.replace("[uwb]\n", "[uwb]\nmultipath_tau_s = -1.0\n"))
    with pytest.raises(ConfigError, match=r"uwb\.multipath_tau_s must be a finite number > 0"):
        load_landing(path)
