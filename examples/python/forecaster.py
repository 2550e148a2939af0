#!/usr/bin/env python3
"""An external hand-force forecaster for upc, in Python (iceoryx2 Python bindings).

It mirrors the channel contract of services/CHANNELS.md with ctypes: it follows the
simulator's time on `<prefix>/state` and publishes `upc::ForecastMsg` windows on
`<prefix>/forecast`. Its force model is its own: one raised-cosine impact on the hand, pushing
toward the robot (−x), as an estimator in a lab would publish from its own knowledge.

    python3 examples/python/forecaster.py --prefix upc --peak 50 --start 1.0 --until 4.0

`upc run --forecaster "python3 examples/python/forecaster.py"` starts it in place of the
built-in forecaster, with UPC_PREFIX and UPC_DURATION set.
"""

import argparse
import math
import os
import signal
import sys
import time
from pathlib import Path

import iceoryx2 as iox2

# The contract's payloads and service settings: services/python/upc_channels.py of the source
# tree, or a copy beside this script (as a MuJoCo plant bundle has one).
_HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(_HERE), str(_HERE.parent.parent / "services" / "python")]
from upc_channels import MAX_FORECAST, ForecastMsg, StateMsg, event, pubsub  # noqa: E402


def impact(t: float, start: float, rise: float, hold: float, fall: float, peak: float) -> float:
    """Raised-cosine rise, plateau, raised-cosine fall (the shape of the embedded scenarios)."""
    tau = t - start
    if tau <= 0 or tau >= rise + hold + fall:
        return 0.0
    if tau < rise:
        return peak * 0.5 * (1 - math.cos(math.pi * tau / rise))
    if tau <= rise + hold:
        return peak
    return peak * 0.5 * (1 + math.cos(math.pi * (tau - rise - hold) / fall))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--prefix", default=os.environ.get("UPC_PREFIX", "upc"))
    p.add_argument("--until", type=float, default=float(os.environ.get("UPC_DURATION", "4.0")))
    p.add_argument("--peak", type=float, default=50.0, help="impact peak force toward the robot (N)")
    p.add_argument("--start", type=float, default=1.0)
    p.add_argument("--rise", type=float, default=0.3)
    p.add_argument("--hold", type=float, default=0.15)
    p.add_argument("--fall", type=float, default=0.4)
    p.add_argument("--dt", type=float, default=0.005)
    p.add_argument("--window", type=float, default=2.5)
    p.add_argument("--period", type=float, default=0.01, help="simulated time between windows (s)")
    a = p.parse_args()

    stop = {"now": False}
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.update(now=True))

    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    publisher = pubsub(node, a.prefix, "forecast", ForecastMsg).publisher_builder().create()
    notifier = event(node, a.prefix, "forecast").notifier_builder().create()
    states = pubsub(node, a.prefix, "state", StateMsg).subscriber_builder().create()
    n = min(MAX_FORECAST, int(math.ceil(a.window / a.dt)))

    # Window k starts at k * period and is published once the plant's time reaches it: its
    # content depends on simulated time only, and with `period` set a lockstep controller waits
    # for it, so a lockstep run with this forecaster reproduces (services/CHANNELS.md).
    seq, now, last_k, session, start, scale = 0, None, None, 0, None, 1.0
    last_state = time.monotonic()
    while not stop["now"]:
        while True:
            sample = states.receive()
            if sample is None:
                break
            st = sample.payload().contents
            if st.session != session:  # a new plant run: publish for its timeline at once
                session, last_k = st.session, None
            # The plant's scenario clock (negative: not started, nothing pushes yet).
            s0 = st.scenario_start if st.scenario_start >= 0 else None
            if s0 != start:
                start, last_k = s0, None
            # The plant pushes its robot this much harder than the scenario's figures.
            scale = st.force_scale if st.force_scale > 0 else 1.0
            now = st.time
            last_state = time.monotonic()
        k = None if now is None else math.floor(now / a.period + 1e-6)
        if k is not None and k != last_k:
            last_k = k
            seq += 1
            t0 = k * a.period
            # scenario_hash 0: this forecast is its own model, not one of upc's scenarios.
            msg = ForecastMsg(seq=seq, t0=t0, dt=a.dt, len=n, period=a.period, scenario_hash=0)
            if start is not None:
                for i in range(n):
                    t = t0 - start + i * a.dt
                    msg.forces[i][0] = -scale * impact(t, a.start, a.rise, a.hold, a.fall, a.peak)
            publisher.loan_uninit().write_payload(msg).send()
            notifier.notify()
        # Done at the end of the run, or when the simulator has gone quiet.
        # Done once the window covering `until` is out (a lockstep controller waits for it).
        if (now is not None and now >= a.until - 1e-9) or (
            seq > 1 and time.monotonic() - last_state > 5.0
        ):
            break
        node.wait(iox2.Duration.from_millis(2))
    print(f"python forecaster: {seq} windows published", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
