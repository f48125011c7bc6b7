"""``swarm replay DIR``: the IMU-driven filter over a recorded UWB + IMU log; ``swarm synth-log DIR``: a
synthetic log with what real ones have (``docs/logs.md``)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from swarm import cpu_latency
from swarm.args import add_output_file, positive_float, seed
from swarm.config import parse_override
from swarm.transport.session import add_zenoh_arguments

REPLAY = """Run the IMU-driven error-state filter over a recorded log (a folder of CSV files and a log.toml,
docs/logs.md) as fast as it can: calibration from the static segment, IMU-driven propagation, ranges with
per-anchor biases, robust NLOS weighting, divergence detection and recovery. Writes the estimate series
(--series); with a truth.csv, reports the 3-D and per-axis RMSE, the NEES and NIS against their chi-square
bands and the rejections per anchor (--json for all of it). With --zenoh it runs no filter: it publishes
the log on the swarm's keys at --speed times real time, as sensor drivers would (imu with the specific
force, uwb, the anchors), so that a process of the swarm runs on recorded sensors."""


def _speed(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--speed must be a number > 0 or inf, got {text!r}") from None
    if not v > 0 or math.isnan(v):
        raise argparse.ArgumentTypeError(f"--speed must be a number > 0 or inf, got {text!r}")
    return v


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay", help="run the estimator over a recorded sensor log (docs/logs.md)", description=REPLAY
    )
    p.add_argument(
        "log",
        type=Path,
        metavar="DIR|FILE.mcap",
        help="a log folder (imu.csv, uwb.csv, anchors.csv, ...), or a recording of `swarm record`",
    )
    p.add_argument(
        "--lockstep",
        default=None,
        metavar="ID",
        help="FILE.mcap: pace the replay by agent ID's commands (tick k once it has sent the command of its "
        "last control tick before k, as the recording has them)",
    )
    p.add_argument(
        "--only",
        default=None,
        metavar="KEY,KEY",
        help="FILE.mcap: publish only these keys (fnmatch patterns, e.g. '*/imu,*/uwb')",
    )
    add_output_file(p, "--json", "write the report as JSON")
    add_output_file(p, "--series", "the estimate series as CSV (default estimate.csv; '-' for none)",
                    default=Path("estimate.csv"), dash=True)  # fmt: skip
    add_output_file(p, "--plot", "trajectory, error and rejections", metavar="FILE.png")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a log.toml key, e.g. --set estimator.huber_k=0 (repeatable)",
    )
    p.add_argument(
        "--sensors",
        default=None,
        metavar="FILE|NAME",
        help="a sensor profile (swarm fit's sensors.toml, or a bundled name such as real-crazyflie) as the "
        "filter's prior; log.toml and --set keys win (docs/logs.md)",
    )
    z = p.add_argument_group("publishing the log on a swarm (--zenoh)")
    z.add_argument(
        "--zenoh", action="store_true", help="publish the log on the swarm's keys instead of filtering"
    )
    z.add_argument(
        "--speed",
        type=_speed,
        default=1.0,
        metavar="N",
        help="times real time (default 1; 'inf' for as fast as possible, a recording only)",
    )
    z.add_argument("--vehicle", default="uav", metavar="ID", help="the vehicle id of the keys (default uav)")
    z.add_argument("--namespace", default="tpods", help="key namespace of the swarm (default tpods)")
    z.add_argument(
        "--wait",
        type=positive_float("--wait"),
        default=5.0,
        metavar="S",
        help="wait this long for a subscriber of the IMU key before starting (default 5 s)",
    )
    add_zenoh_arguments(z)
    cpu_latency.add_argument(z)  # a paced publisher sleeps between samples, as a sensor driver does
    p.set_defaults(func=run)

    s = sub.add_parser(
        "synth-log",
        help="write a synthetic UWB + IMU flight log (docs/logs.md)",
        description="A synthetic flight log made by swarm.logs.synthetic: 1 kHz IMU with "
        "biases, 8 anchors with drifting range biases, one NLOS anchor, dropouts, jitter, truth.",
    )
    s.add_argument("out", type=Path, metavar="DIR", help="the folder to write (created)")
    s.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    s.add_argument(
        "--duration",
        type=positive_float("--duration"),
        default=60.0,
        metavar="S",
        help="flight length [s] (default 60)",
    )
    s.add_argument(
        "--vision",
        type=positive_float("--vision"),
        default=None,
        metavar="HZ",
        help="add a downward camera seeing floor markers at HZ frames per second (vision.csv, markers.csv)",
    )
    s.add_argument(
        "--profile",
        default=None,
        metavar="NAME|FILE",
        help="draw the range errors and IMU noise from this sensor profile (a sensors.toml, or a bundled "
        "name such as real-crazyflie): offsets, take-off step, multipath, NLOS episodes, vibration "
        "(default: the synthetic model)",
    )
    s.add_argument(
        "--height",
        type=positive_float("--height"),
        default=None,
        metavar="HZ",
        help="add a downward range finder at HZ (height.csv)",
    )
    s.add_argument(
        "--baro",
        type=positive_float("--baro"),
        default=None,
        metavar="HZ",
        help="add a barometer at HZ (baro.csv)",
    )
    s.add_argument(
        "--tdoa",
        choices=("tdoa2", "tdoa3"),
        default=None,
        help="a passive tag on the Loco Positioning TDoA radio: tdoa.csv instead of two-way ranges (uwb.csv "
        "without rows; with --profile its range errors, per anchor, as differences)",
    )
    s.add_argument(
        "--tdoa-nlos",
        dest="tdoa_nlos",
        type=int,
        default=None,
        metavar="ANCHOR",
        help="with --tdoa: this anchor's packets in flight are often long (all its pairs)",
    )
    s.set_defaults(func=run_synth)


def run_synth(args: argparse.Namespace) -> int:
    from swarm.errors import ConfigError
    from swarm.logs.synthetic import SyntheticSpec, make_log

    spec = SyntheticSpec(
        duration_s=args.duration,
        vision_rate_hz=args.vision or 0.0,
        height_rate_hz=args.height or 0.0,
        baro_rate_hz=args.baro or 0.0,
        tdoa=args.tdoa or "",
        tdoa_nlos_anchor=args.tdoa_nlos,
    )
    if args.tdoa_nlos is not None and not args.tdoa:
        raise ConfigError("--tdoa-nlos needs --tdoa tdoa2|tdoa3")
    profile = None
    if args.profile is not None:
        from swarm.sensors.profile import load_profile

        profile = load_profile(args.profile)
    if args.duration <= spec.static_s + spec.takeoff_s:
        raise ConfigError(
            f"--duration must exceed the static segment and take-off ({spec.static_s + spec.takeoff_s:g} s), "
            f"got {args.duration:g}"
        )
    make_log(args.out, args.seed, spec, profile)
    files = (
        "imu.csv, uwb.csv, anchors.csv, truth.csv, "
        + ("tdoa.csv, " if args.tdoa else "")
        + ("vision.csv, markers.csv, " if args.vision else "")
        + ("height.csv, " if args.height else "")
        + ("baro.csv, " if args.baro else "")
    )
    what = "" if profile is None else f", sensor profile {profile.name!r}"
    print(f"wrote {args.out}/ ({files}log.toml): {args.duration:g} s, seed {args.seed}{what}")
    return 0


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.3f}"


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from swarm.logs.reader import read_log
    from swarm.logs.replay import replay_log

    if args.log.suffix == ".mcap":
        return _publish_recording(args)
    overrides = dict(parse_override(o) for o in args.overrides)
    if args.sensors is not None:
        from swarm.logs.prior import with_profile
        from swarm.sensors.profile import load_profile

        overrides = with_profile(args.log, load_profile(args.sensors), overrides)
    log = read_log(args.log, overrides)
    if args.zenoh:
        return _publish(log, args)
    result = replay_log(log)
    s = result.summary()
    print(
        f"{log.path}: {s['duration_s']:.1f} s, {s['imu_samples']} IMU samples, {s['ranges']} ranges, "
        f"replayed in {s['replay_wall_s']:.3f} s"
    )
    if s["skipped_rows"]:
        print(
            "  skipped rows (NaN or empty samples): "
            + ", ".join(f"{k} {v}" for k, v in s["skipped_rows"].items())
        )
    if s["dropped_out_of_order"]:
        print(f"  samples older than the filter, dropped: {s['dropped_out_of_order']}")
    if "rmse_m" in s:
        lo, hi = s["nees_band"]
        print(
            f"  RMSE {s['rmse_m']:.3f} m 3-D (x {s['rmse_axis_m'][0]:.3f}, y {s['rmse_axis_m'][1]:.3f}, "
            f"z {s['rmse_axis_m'][2]:.3f}); attitude {s['attitude_rmse_deg']:.2f} deg RMS"
        )
        print(
            f"  position NEES mean {s['nees_mean']:.2f} (3 expected), inside its 95 % band "
            f"[{lo:.2f}, {hi:.2f}] "
            f"{s['nees_in_band_share']:.0%} of the time"
        )
    lo1, hi1 = s["nis_band"]
    print(
        f"  range NIS mean {_fmt(s['nis_mean'])} (1 expected), inside [{lo1:.3f}, {hi1:.2f}] "
        f"{(s['nis_in_band_share'] or 0):.0%} of accepted ranges"
    )
    v = s.get("vision")
    if v is not None and v["used"]:
        print(
            f"  vision: {v['accepted']} of {v['detections']} detections accepted, {v['rejected']} rejected; "
            f"NIS mean {_fmt(v['nis_mean'])} (3 expected), inside [{v['nis_band'][0]:.3f}, "
            f"{v['nis_band'][1]:.2f}] {(v['nis_in_band_share'] or 0):.0%} of accepted"
        )
    elif v is not None:
        print(f"  vision: {v['detections']} detections not used (vision.enabled = false)")
    print("  anchor  accepted  rejected  refused  rejected share  range bias [m]")
    for a, c in s["counts_by_anchor"].items():
        share = s["rejected_share_by_anchor"][a]
        bias = s["range_bias_m"].get(a)
        print(
            f"  {a:>6}  {c['accepted']:8d}  {c['rejected']:8d}  {c['refused']:7d}  "
            f"{'-' if share is None else f'{share:14.1%}'}  {_fmt(bias):>14}"
        )
    for ev in s["events"]:
        print(
            f"  event at {ev['t_s']:.2f} s: {ev['kind']}"
            + (f": {ev['reason']}; {ev['action']}" if "reason" in ev else "")
        )
    if str(args.series) != "-":
        cols, rows = result.series()
        np.savetxt(args.series, rows, delimiter=",", header=",".join(cols), comments="", fmt="%.9g")
        print(f"wrote {args.series} ({len(rows)} rows)")
    if args.json is not None:
        args.json.write_text(json.dumps(s, indent=2, allow_nan=False, default=_json_default) + "\n")
        print(f"wrote {args.json}")
    if args.plot is not None:
        _plot(result, args.plot)
        print(f"wrote {args.plot}")
    return 0


def _publish_recording(args: argparse.Namespace) -> int:
    """``swarm replay FILE.mcap``: every recorded message again on its key, paced by ``--speed`` (swarm
    time; ``--speed inf``: as fast as possible)."""
    import threading

    from swarm.transport.keys import Keys, check_id
    from swarm.transport.recording import LockstepAck, read_recording, recorded_ticks, replay_recording
    from swarm.transport.session import open_session, zenoh_args_from

    messages, _meta = read_recording(args.log)
    only = tuple(p for p in (args.only or "").split(",") if p)
    stop = threading.Event()
    with cpu_latency.hold(args.cpu_latency), open_session(zenoh_args_from(args)) as session:
        print(f"replaying {args.log}: {len(messages)} messages at {args.speed:g}x", flush=True)
        ack = None
        if args.lockstep is not None:
            check_id(args.lockstep, "--lockstep")
            key = Keys(args.namespace).command(args.lockstep)
            # the agent commands on its control ticks: those its recorded commands name
            ack = LockstepAck(session, key, ticks=recorded_ticks(messages, key) or None)
        try:
            sent = replay_recording(messages, session, args.speed, stop, only, ack)
        except KeyboardInterrupt:
            stop.set()
            return 130
    print(f"sent {sum(sent.values())} messages on {len(sent)} keys", flush=True)
    return 0


def _publish(log, args: argparse.Namespace) -> int:
    import threading

    from swarm.transport.keys import Keys, check_id
    from swarm.transport.logfeed import feed
    from swarm.transport.session import open_session, zenoh_args_from

    check_id(args.vehicle, "--vehicle")
    keys = Keys(args.namespace)
    stop = threading.Event()
    with cpu_latency.hold(args.cpu_latency), open_session(zenoh_args_from(args)) as session:
        print(
            f"publishing {log.path} as {keys.imu(args.vehicle)} and uwb at {args.speed:g}x real time",
            flush=True,
        )
        try:
            out = feed(log, session, keys, args.vehicle, args.speed, stop, args.wait)
        except KeyboardInterrupt:
            stop.set()
            return 130
    print(
        f"sent {out['imu']} imu, {out['uwb']} uwb and {out['vision']} vision samples: "
        f"{out['log_s']:.1f} s of log in {out['wall_s']:.1f} s",
        flush=True,
    )
    return 0


def _json_default(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    raise TypeError(f"not JSON: {v!r}")


def _plot(result, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    lg = result.log
    fig, ax = plt.subplots(1, 3, figsize=(16, 5))
    if lg.truth_p is not None:
        ax[0].plot(lg.truth_p[:, 0], lg.truth_p[:, 1], "k-", lw=1, label="truth")
    ax[0].plot(result.X[:, 0], result.X[:, 1], "C0-", lw=1, label="estimate")
    ax[0].plot(lg.anchors_nav[:, 0], lg.anchors_nav[:, 1], "r^", label="anchors")
    ax[0].set(xlabel="x [m]", ylabel="y [m]", title="trajectory (top view)", aspect="equal")
    ax[0].legend()
    sig = np.sqrt(np.diagonal(result.P[:, 0:3, 0:3], axis1=1, axis2=2))
    err = result.errors()
    for k, name in enumerate("xyz"):
        if err is not None:
            inside, e, _ = err
            ax[1].plot(result.t[inside], e[:, k], f"C{k}-", lw=0.8, label=f"{name} error")
        ax[1].plot(result.t, 3 * sig[:, k], f"C{k}:", lw=0.8)
        ax[1].plot(result.t, -3 * sig[:, k], f"C{k}:", lw=0.8)
    for ev in result.events:
        ax[1].axvline(ev["t_s"], color="r", lw=0.8)
    ax[1].set(xlabel="t [s]", ylabel="[m]", title="position error and 3 sigma" if err else "3 sigma")
    ax[1].legend()
    c = result.counts
    ids = [str(int(i)) for i in lg.anchor_ids]
    ax[2].bar(np.arange(len(ids)), c[:, 1] / np.maximum(c[:, 0] + c[:, 1], 1), tick_label=ids)
    ax[2].set(xlabel="anchor", ylabel="rejected share", title="ranges rejected by the gate")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
