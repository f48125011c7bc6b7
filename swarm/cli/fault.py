"""``swarm fault KIND ...``: inject a fault into a running swarm (issue 7) over ``<ns>/control/fault``.

The world applies camera and gyro faults, the mothership UWB ones, each from its next tick on (never to a
sample already sent); a landing swarm's world applies camera_loss and uwb_dropout to one UAV or all.
Examples, against ``swarm launch ... --listen tcp/127.0.0.1:7447``::

    swarm fault uwb_dropout --for 5 --connect tcp/127.0.0.1:7447
    swarm fault nlos_burst --for 10 --probability 0.2 --connect tcp/127.0.0.1:7447
    swarm fault camera_loss --vehicle chaser --for 3 --connect tcp/127.0.0.1:7447
    swarm fault gyro_bias_step --vehicle chaser --rate-deg-s 0.5,0,0 --connect tcp/127.0.0.1:7447
    swarm fault sensor_delay --vehicle chaser --for 5 --delay 0.05 --connect ...   # realtime/scaled only
    swarm fault camera_loss --vehicle uav1 --at 9 --for 3 --connect ...           # a landing swarm
"""

from __future__ import annotations

import argparse
import math
import time

from swarm.errors import ConfigError

DESCRIPTION = __doc__.split("\n\n")[1]


def _rate(text: str) -> tuple[float, float, float]:
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--rate-deg-s must be three numbers x,y,z, got {text!r}") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise argparse.ArgumentTypeError(f"--rate-deg-s must be three finite numbers x,y,z, got {text!r}")
    return v  # type: ignore[return-value]


def add_parser(sub: argparse._SubParsersAction) -> None:
    from swarm.args import positive_float
    from swarm.transport.messages import FAULT_KINDS
    from swarm.transport.session import add_zenoh_arguments

    p = sub.add_parser("fault", help="inject a fault into a running swarm", description=DESCRIPTION)
    p.add_argument("kind", choices=FAULT_KINDS, help="the fault")
    p.add_argument("--for", dest="duration", type=positive_float("--for"), default=None, metavar="S",
                   help="length of the window [s] (required but for gyro_bias_step)")  # fmt: skip
    p.add_argument("--at", type=positive_float("--at"), default=None, metavar="S",
                   help="simulated time the window opens [s] (default: at once)")  # fmt: skip
    p.add_argument(
        "--vehicle",
        default=None,
        help="camera_loss / gyro_bias_step (a landing swarm: camera_loss / uwb_dropout): the vehicle "
        "(default: every chaser, every UAV)",
    )
    p.add_argument(
        "--probability", type=float, default=None, help="nlos_burst: outlier probability in (0, 1]"
    )
    p.add_argument("--rate-deg-s", type=_rate, default=None, metavar="X,Y,Z",
                   help="gyro_bias_step: the added rate [deg/s], body frame")  # fmt: skip
    p.add_argument("--delay", type=positive_float("--delay"), default=None, metavar="S",
                   help="sensor_delay: samples leave up to this late [s] (free-running clocks)")  # fmt: skip
    p.add_argument("--namespace", default="tpods", help="key namespace of the swarm (default tpods)")
    p.add_argument("--wait", type=positive_float("--wait"), default=5.0, metavar="S",
                   help="how long to wait for the swarm to be listening (default 5 s)")  # fmt: skip
    add_zenoh_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import zenoh

    from swarm.errors import MessageError
    from swarm.transport.keys import Keys
    from swarm.transport.messages import Fault, encode
    from swarm.transport.session import open_session, zenoh_args_from

    rate = None if args.rate_deg_s is None else [math.radians(x) for x in args.rate_deg_s]
    try:
        msg = Fault(args.kind, args.duration, args.at, args.vehicle, args.probability, rate, args.delay)
    except MessageError as exc:  # name the flag behind the field
        flags = {"duration_s": "--for", "start_s": "--at", "vehicle": "--vehicle", "delay_s": "--delay",
                 "probability": "--probability", "rate_rad_s": "--rate-deg-s"}  # fmt: skip
        field = str(exc).split(":")[0]
        raise ConfigError(f"{flags.get(field, field)}: {str(exc).split(': ', 1)[-1]}") from None
    keys = Keys(args.namespace)
    with open_session(zenoh_args_from(args)) as session:
        pub = session.declare_publisher(
            keys.fault(),
            reliability=zenoh.Reliability.RELIABLE,
            congestion_control=zenoh.CongestionControl.BLOCK,
        )
        deadline = time.monotonic() + args.wait
        while not pub.matching_status.matching:
            if time.monotonic() > deadline:
                raise ConfigError(
                    f"--wait: nobody listens on {keys.fault()} after {args.wait:g} s (is the swarm up?)"
                )
            time.sleep(0.01)
        pub.put(encode(msg))
        time.sleep(0.2)  # let the sample leave before the session closes
    print(f"fault sent: {args.kind} on {keys.fault()}", flush=True)
    return 0
