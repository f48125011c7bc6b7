"""``swarm fit LOG --out sensors.toml``: a sensor profile measured on a log with a truth (docs/logs.md,
"Fitting a sensor profile")."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from swarm.args import add_output_file
from swarm.config import parse_override

FIT = """Measure a sensor profile (sensors.toml: the range error model and the IMU noise) on a log folder
with a truth.csv: per anchor, the range residual's bias and robust sigma on the ground and in flight, the
NLOS episodes, the time-correlated (Gauss-Markov) part; the IMU's white noise and bias instability from the
Allan deviation of the static segment before take-off, and the in-flight vibration. Prints a table, writes
the profile (--out), the numbers (--json) and the figures to check them against (--plot DIR)."""


def _finite(flag: str):
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} must be a number, got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"{flag} must be a finite number, got {text!r}")
        return v

    return parse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="measure a sensor profile on a log with a truth (docs/logs.md)",
                       description=FIT)  # fmt: skip
    p.add_argument("log", type=Path, metavar="LOG", help="a log folder with truth.csv (docs/logs.md)")
    add_output_file(
        p, "--out", "the sensor profile to write (default sensors.toml)", default=Path("sensors.toml")
    )
    p.add_argument("--plot", type=Path, default=None, metavar="DIR",
                   help="write residuals.png, autocorrelation.png, allan.png into DIR (created)")  # fmt: skip
    p.add_argument("--static-until", type=_finite("--static-until"), default=None, metavar="S",
                   help="the IMU's static segment ends at this log time [s] (default: 2 s before "
                   "take-off)")  # fmt: skip
    add_output_file(p, "--json", "write every number as JSON")
    p.add_argument("--name", default=None, help="the profile's name (default: the --out file's stem)")
    p.add_argument("--source", default=None, help="the profile's source line (default: the log and its size)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="a fit parameter (swarm.logs.fit.FitParams), e.g. --set airborne_height_m=0.05; "
                   "or a log.toml key, e.g. --set estimator.lever_arm_m=[0,0,0.02] (repeatable)")  # fmt: skip
    p.set_defaults(func=run)


def _f(v, digits: int = 3) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def table(result) -> list[str]:
    """The human summary: per anchor, ground vs flight bias and sigma, the GM split and NLOS."""
    head = ("anchor", "n gnd", "n fly", "gnd bias", "gnd sig", "fly bias", "fly sig", "step", "white",
            "GM sig", "tau s", "NLOS %", "episodes")  # fmt: skip
    width = (6, 6, 6, 9, 8, 9, 8, 7, 6, 6, 6, 6, 8)
    lines = [" ".join(f"{h:>{w}}" for h, w in zip(head, width, strict=True))]
    for a in result.anchors:
        row = (a.anchor_id, a.ground_n, a.flight_n, _f(a.ground_bias_m), _f(a.ground_sigma_m),
               _f(a.flight_bias_m), _f(a.flight_sigma_m), _f(a.flight_bias_m - a.ground_bias_m),
               _f(a.gm.white_sigma_m), _f(a.gm.gm_sigma_m), _f(a.gm.gm_tau_s, 2), _f(100 * a.nlos_share, 1),
               a.nlos_episodes)  # fmt: skip
        lines.append(" ".join(f"{v:>{w}}" for v, w in zip(row, width, strict=True)))
    return lines


def run(args: argparse.Namespace) -> int:
    from swarm.config import from_mapping
    from swarm.logs.fit import FitParams, fit_log
    from swarm.logs.reader import read_log
    from swarm.sensors.profile import save_profile

    pairs = [parse_override(o) for o in args.overrides]
    fit_keys = {f for f in FitParams.__dataclass_fields__}
    fit_over = {k: v for k, v in pairs if k in fit_keys}
    if args.static_until is not None:
        fit_over["static_until_s"] = args.static_until
    prm = from_mapping(FitParams, fit_over, "fit")
    log = read_log(args.log, {k: v for k, v in pairs if k not in fit_keys})
    name = args.name or args.out.stem
    result = fit_log(log, prm, source=args.source or "", name=name)
    p = result.profile
    print(
        f"{log.path}: {result.ranges} ranges ({result.ranges_unused} unused), take-off at "
        f"{result.takeoff_s:.1f} s, landing at {_f(result.landing_s, 1)} s, {result.flight_s:.1f} s of "
        f"flight; IMU static segment {result.static_s[0]:.1f}-{result.static_s[1]:.1f} s"
    )
    for line in table(result):
        print("  " + line)
    u, i = p.uwb, p.imu
    print(
        f"  ranges: offset {u.offset_m:.3f} m (spread {u.offset_spread_m:.3f}), take-off step "
        f"{u.takeoff_step_m:+.3f} m (spread {u.takeoff_step_spread_m:.3f}); sigma ground "
        f"{u.ground_sigma_m:.3f} m, flight white {u.sigma_m:.3f} m + GM {u.gm_sigma_m:.3f} m, tau "
        f"{u.gm_tau_s:.2f} s; NLOS {u.nlos_rate_hz:.3f}/s x {u.nlos_duration_s:.1f} s, "
        f"+{u.nlos_excess_m:.2f} m; outliers {100 * u.outlier_share:.2f} %"
    )
    print(
        f"  IMU {i.rate_hz:.0f} Hz: gyro N {i.gyro_noise_rad_s_rthz:.3g} rad/s/rtHz, "
        f"B {i.gyro_bias_instability_rad_s:.2g} rad/s, vibration {i.gyro_vibration_rad_s:.3g} rad/s; "
        f"accel N {i.accel_noise_m_s2_rthz:.3g} m/s^2/rtHz, B {i.accel_bias_instability_m_s2:.2g} m/s^2, "
        f"vibration {i.accel_vibration_m_s2:.3g} m/s^2"
    )
    for note in result.notes:
        print(f"  note: {note}")
    save_profile(p, args.out, comments=[f"swarm fit {args.log}", *(f"note: {n}" for n in result.notes)])
    print(f"wrote {args.out}")
    if args.json is not None:
        args.json.write_text(json.dumps(result.summary() | {"profile": _profile_json(p)}, indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.plot is not None:
        from swarm.logs.fit_plot import plot_fit

        for path in plot_fit(result, args.plot):
            print(f"wrote {path}")
    return 0


def _profile_json(p) -> dict:
    from swarm.config import to_mapping

    return to_mapping(p)
