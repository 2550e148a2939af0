#!/usr/bin/env python3
"""The soak's scenario (scripts/soak.sh): a scenario's impacts repeated every 8 s for the whole
soak, or none (quiet).

    soak_scenario.py BASE.toml DURATION_S QUIET(0|1) > soak.toml
"""

import sys
import tomllib

PERIOD = 8.0  # s: multiple_impacts' pushes end by 5.8 s; the robot settles before the next


def main() -> int:
    base = tomllib.load(open(sys.argv[1], "rb"))
    duration, quiet = float(sys.argv[2]), sys.argv[3] == "1"
    out = ['name = "soak"', "", "zmp_reference = [0.0, 0.0]", "[force]", 'kind = "impacts"']
    if quiet:
        out.append("impacts = []")
    k = 0
    while not quiet and PERIOD * k < duration + PERIOD:
        for i in base["force"]["impacts"]:
            out.append("[[force.impacts]]")
            out.append(f"start = {i['start'] + PERIOD * k}")
            for key in ("rise", "hold", "fall"):
                out.append(f"{key} = {i.get(key, 0.0)}")
            out.append(f"force = {list(i['force'])}")
        k += 1
    # The scenario lasts the soak (its processes are given their own durations), its last
    # repetition included.
    out[1] = f"duration = {max(duration, PERIOD * k)}"
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
