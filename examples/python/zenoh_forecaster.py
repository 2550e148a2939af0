#!/usr/bin/env python3
"""A remote hand-force forecaster for upc over Zenoh (eclipse-zenoh): it runs on any host that
reaches the robot's `upc bridge`, and needs no iceoryx2.

It follows the plant's time on `<key_prefix>/state` (the bridge forwards every `decimation`-th
state) and puts `upc::ForecastMsg` windows on `<key_prefix>/forecast`, framed as in
services/CHANNELS.md ("Over Zenoh"). Its model is a scenario file of upc (the impacts, or the
CSV samples, of config/scenarios/*.toml), evaluated as upc's own forecaster does: with the same
windows (k·period, once the plant's time reaches it) a lockstep run gives the same bytes as with
`upc forecast`.

    python3 examples/python/zenoh_forecaster.py --connect tcp/ROBOT:7447 --scenario multiple_impacts

To a bridge with TLS (services/BRIDGE_SECURITY.md), with this forecaster's certificate, whose
common name is its identity: it then puts on `<key_prefix>/forecast/<name>`, the only forecast
key the bridge lets that identity use.

    python3 examples/python/zenoh_forecaster.py --connect tls/robot.lab:7447 --mode client \
        --ca pki/ca.pem --cert pki/fc1.pem --key pki/fc1.key --name fc1

`upc run --forecaster-over-zenoh` starts a bridge and this script on loopback.
"""

import argparse
import json
import math
import os
import signal
import sys
import threading
import time
import tomllib
from pathlib import Path

import zenoh

# The contract's payloads: services/python/upc_channels.py of the source tree, or a copy beside
# this script (`upc run` writes one into the run directory).
_HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(_HERE), str(_HERE.parent.parent / "services" / "python")]
from upc_channels import MAX_FORECAST, ForecastMsg, StateMsg, WireError, wire_decode, wire_encode  # noqa: E402


def envelope(imp: dict, t: float) -> float:
    """upc's impact envelope (src/scenario/profile.rs), operation for operation."""
    tau = t - imp["start"]
    r, h, f = imp["rise"], imp.get("hold", 0.0), imp["fall"]
    if tau <= 0.0 or tau >= r + h + f:
        return 0.0
    if tau < r:
        return 0.5 * (1.0 - math.cos(math.pi * tau / r))
    if tau <= r + h:
        return 1.0
    return 0.5 * (1.0 + math.cos(math.pi * (tau - r - h) / f))


class Profile:
    """A scenario's hand force over time, × the plant's force scale."""

    def __init__(self, path: Path, scale: float):
        doc = tomllib.loads(path.read_text())
        self.name = doc["name"]
        force = doc["force"]
        self.impacts, self.samples = None, None
        if force["kind"] == "impacts":
            self.impacts = [dict(i) for i in force["impacts"]]
            if scale != 1.0:
                for i in self.impacts:
                    i["force"] = [f * scale for f in i["force"]]
        elif force["kind"] == "csv":
            csv = Path(force["path"])
            csv = csv if csv.is_absolute() else path.parent / csv
            self.samples = []
            for n, line in enumerate(csv.read_text().splitlines()):
                line = line.split("#")[0].strip()
                if not line:
                    continue
                try:
                    t, fx, fy, fz = (float(x) for x in line.split(","))
                except ValueError:
                    if n == 0 and not self.samples:
                        continue  # header
                    raise
                f = [fx, fy, fz]
                self.samples.append((t, [x * scale for x in f] if scale != 1.0 else f))
        else:
            raise ValueError(f"{path}: force kind {force['kind']!r} is not known to this forecaster")

    def at(self, t: float):
        if self.impacts is not None:
            f = [0.0, 0.0, 0.0]
            for imp in self.impacts:
                e = envelope(imp, t)
                for c in range(3):
                    f[c] += e * imp["force"][c]
            return f
        s = self.samples
        i = next((k for k, (ts, _) in enumerate(s) if ts > t), len(s))
        if i == 0 or i == len(s):
            return [0.0, 0.0, 0.0]
        (t0, f0), (t1, f1) = s[i - 1], s[i]
        w = (t - t0) / (t1 - t0)
        return [f0[c] + w * (f1[c] - f0[c]) for c in range(3)]


def resolve(scenario: str, scenario_dir: Path) -> Path:
    """A scenario path, or an embedded name looked up in `scenario_dir`."""
    p = Path(scenario)
    if p.suffix == ".toml" or "/" in scenario:
        return p
    return scenario_dir / f"{scenario}.toml"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", action="append",
                   default=[e for e in os.environ.get("UPC_ZENOH_CONNECT", "").split(",") if e],
                   help="Zenoh endpoint of the bridge (repeatable), e.g. tcp/10.0.0.2:7447")
    p.add_argument("--mode", default="peer", choices=["peer", "client"])
    p.add_argument("--key-prefix", default=os.environ.get("UPC_PREFIX", "upc"))
    p.add_argument("--name", default=os.environ.get("UPC_ZENOH_NAME", ""),
                   help="this forecaster's identity: puts on <key_prefix>/forecast/<name> "
                        "(a bridge with TLS takes forecasts only there; default: <key_prefix>/forecast)")
    p.add_argument("--ca", default=os.environ.get("UPC_ZENOH_CA"), help="the lab's CA certificate (PEM): TLS")
    p.add_argument("--cert", default=os.environ.get("UPC_ZENOH_CERT"), help="this forecaster's certificate (PEM)")
    p.add_argument("--key", default=os.environ.get("UPC_ZENOH_KEY"), help="its private key (PEM)")
    p.add_argument("--user", default=os.environ.get("UPC_ZENOH_USER"), help="user name, if the bridge asks for one")
    p.add_argument("--password", default=os.environ.get("UPC_ZENOH_PASSWORD"))
    p.add_argument("--scenario", default=os.environ.get("UPC_SCENARIO"),
                   help="scenario TOML or embedded name (default: the one the plant announces)")
    p.add_argument("--scenario-dir", type=Path,
                   default=Path(os.environ.get("UPC_SCENARIO_DIR", _HERE.parent.parent / "config" / "scenarios")))
    p.add_argument("--until", type=float, default=float(os.environ.get("UPC_DURATION", "inf")))
    p.add_argument("--dt", type=float, default=0.005)
    p.add_argument("--window", type=float, default=2.5)
    p.add_argument("--period", type=float, default=0.01, help="simulated time between windows (s)")
    p.add_argument("--summary", type=Path, help="write counts as JSON here at the end")
    a = p.parse_args()

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())

    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(a.mode))
    conf.insert_json5("connect/endpoints", json.dumps(a.connect))
    conf.insert_json5("scouting/multicast/enabled", "false" if a.connect else "true")
    if a.ca:
        tls = "transport/link/tls"
        conf.insert_json5(f"{tls}/root_ca_certificate", json.dumps(a.ca))
        if a.cert and a.key:
            conf.insert_json5(f"{tls}/connect_certificate", json.dumps(a.cert))
            conf.insert_json5(f"{tls}/connect_private_key", json.dumps(a.key))
            conf.insert_json5(f"{tls}/enable_mtls", "true")
        conf.insert_json5(f"{tls}/verify_name_on_connect", "true")
    if a.user:
        conf.insert_json5("transport/auth/usrpwd/user", json.dumps(a.user))
        conf.insert_json5("transport/auth/usrpwd/password", json.dumps(a.password or ""))
    session = zenoh.open(conf)

    latest = {"state": None, "refused": 0}
    arrived = threading.Event()

    def on_state(sample):
        try:
            latest["state"] = wire_decode("state", sample.payload.to_bytes(), StateMsg)
            arrived.set()
        except WireError as e:
            latest["refused"] += 1
            if latest["refused"] & (latest["refused"] - 1) == 0:
                print(f"zenoh forecaster: state refused: {e}", file=sys.stderr)

    states = session.declare_subscriber(f"{a.key_prefix}/state", on_state)
    publisher = session.declare_publisher(f"{a.key_prefix}/forecast" + (f"/{a.name}" if a.name else ""))
    n = max(1, min(MAX_FORECAST, math.ceil(a.window / a.dt)))

    # As upc's forecaster (src/forecast/mod.rs): window k starts at k·period and is published
    # once the plant's time reaches it; a new plant run or scenario start restarts the count.
    seq, last_k, session_id, start, profile, key = 0, None, 0, 0.0, None, None
    last_state = time.monotonic()
    while not stop.is_set():
        arrived.wait(0.05)
        arrived.clear()
        st = latest["state"]
        if st is None:
            continue
        last_state = time.monotonic()
        if st.session != session_id:
            session_id, last_k = st.session, None
        if st.scenario_start >= 0.0 and st.scenario_start != start:
            start, last_k = st.scenario_start, None
        scale = st.force_scale if st.force_scale > 0.0 else 1.0
        name = a.scenario or bytes(st.scenario).rstrip(b"\0").decode() or "multiple_impacts"
        if (name, scale) != key:
            key, last_k = (name, scale), None
            profile = Profile(resolve(name, a.scenario_dir), scale)
            print(f"zenoh forecaster: forecasting {profile.name} × {scale}", file=sys.stderr)
        now = st.time
        k = math.floor(now / a.period + 1e-6)
        if k != last_k:
            last_k = k
            seq += 1
            t0 = k * a.period
            # scenario_hash 0: a model of its own (the controller compares only non-zero hashes).
            msg = ForecastMsg(seq=seq, t0=t0, dt=a.dt, len=n, period=a.period, scenario_hash=0)
            if st.scenario_start >= 0.0:
                base = t0 - start - 0.0
                for i in range(n):
                    msg.forces[i][:] = profile.at(base + i * a.dt)
            publisher.put(wire_encode("forecast", msg))
        if now >= a.until - 1e-9:
            break
    if time.monotonic() - last_state > 5.0 and seq == 0:
        print("zenoh forecaster: no state arrived (is `upc bridge` reachable?)", file=sys.stderr)
    print(f"zenoh forecaster: {seq} windows published", file=sys.stderr)
    if a.summary:
        a.summary.write_text(json.dumps({"windows": seq, "states_refused": latest["refused"]}))
    states.undeclare()
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
