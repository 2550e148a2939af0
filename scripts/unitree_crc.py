#!/usr/bin/env python3
"""Unitree G1 low-level messages (unitree_hg LowCmd_ / LowState_): CRC and CDR bytes.

An implementation independent of upc's (src/bus/unitree_hg.rs), written from the IDL and
Unitree's CRC description, for tests/unitree_hg_wire.rs to check upc against. Standard library
only. Where upc walks the fields by hand, this derives both layouts from a schema:

- the C-struct image (what the CRC covers): every member at its natural alignment, a struct
  aligned to its widest member and padded to a multiple of it (sizeof LowCmd_ 1004,
  LowState_ 2092);
- the CDR sample on the wire: header 00 01 00 00 (CDR_LE), then every primitive aligned to its
  own size from the start of the payload, structs unpadded, fixed arrays without length.

The CRC is CRC-32 with polynomial 0x04C11DB7, initial 0xFFFFFFFF, no reflection, no final XOR,
over the image's little-endian 32-bit words but the last (the crc itself), each word fed from
bit 31 down to bit 0.

Usage:
    unitree_crc.py [--seal] [JSON]      (JSON from stdin when not given)

JSON: {"type": "LowCmd_" or "LowState_", <fields>...}, field names as in the IDL; a missing
field is zero, an array of structs may be shorter than its length (the rest zero). With
--seal, the computed CRC replaces the crc field in the CDR bytes.

Prints one JSON object: type, image_size, crc, image_hex, cdr_size, cdr_hex.
"""

import json
import struct
import sys

# Primitive: (struct format letter, size in bytes).
PRIMS = {"u8": ("B", 1), "i16": ("h", 2), "u32": ("I", 4), "f32": ("f", 4)}


def struct_t(name, members):
    return ("struct", name, members)


def array_t(elem, n):
    return ("array", elem, n)


IMU_STATE = struct_t("IMUState_", [
    ("quaternion", array_t("f32", 4)),
    ("gyroscope", array_t("f32", 3)),
    ("accelerometer", array_t("f32", 3)),
    ("rpy", array_t("f32", 3)),
    ("temperature", "i16"),
])
MOTOR_STATE = struct_t("MotorState_", [
    ("mode", "u8"),
    ("q", "f32"),
    ("dq", "f32"),
    ("ddq", "f32"),
    ("tau_est", "f32"),
    ("temperature", array_t("i16", 2)),
    ("vol", "f32"),
    ("sensor", array_t("u32", 2)),
    ("motorstate", "u32"),
    ("reserve", array_t("u32", 4)),
])
LOW_STATE = struct_t("LowState_", [
    ("version", array_t("u32", 2)),
    ("mode_pr", "u8"),
    ("mode_machine", "u8"),
    ("tick", "u32"),
    ("imu_state", IMU_STATE),
    ("motor_state", array_t(MOTOR_STATE, 35)),
    ("wireless_remote", array_t("u8", 40)),
    ("reserve", array_t("u32", 4)),
    ("crc", "u32"),
])
MOTOR_CMD = struct_t("MotorCmd_", [
    ("mode", "u8"),
    ("q", "f32"),
    ("dq", "f32"),
    ("tau", "f32"),
    ("kp", "f32"),
    ("kd", "f32"),
    ("reserve", "u32"),
])
LOW_CMD = struct_t("LowCmd_", [
    ("mode_pr", "u8"),
    ("mode_machine", "u8"),
    ("motor_cmd", array_t(MOTOR_CMD, 35)),
    ("reserve", array_t("u32", 4)),
    ("crc", "u32"),
])
TYPES = {"LowCmd_": (LOW_CMD, 1004), "LowState_": (LOW_STATE, 2092)}


def round_up(n, a):
    return (n + a - 1) // a * a


# --- C layout -------------------------------------------------------------------------------


def c_align(t):
    if isinstance(t, str):
        return PRIMS[t][1]
    if t[0] == "array":
        return c_align(t[1])
    return max(c_align(m) for _, m in t[2])


def c_sizeof(t):
    if isinstance(t, str):
        return PRIMS[t][1]
    if t[0] == "array":
        return c_sizeof(t[1]) * t[2]
    off = 0
    for _, m in t[2]:
        off = round_up(off, c_align(m)) + c_sizeof(m)
    return round_up(off, c_align(t))


def c_write(t, value, buf, off):
    """Pack value of type t at offset off (already aligned for t) into buf."""
    if isinstance(t, str):
        struct.pack_into("<" + PRIMS[t][0], buf, off, value)
    elif t[0] == "array":
        size = c_sizeof(t[1])
        for i, v in enumerate(value):
            c_write(t[1], v, buf, off + i * size)
    else:
        pos = 0
        for name, m in t[2]:
            pos = round_up(pos, c_align(m))
            c_write(m, value[name], buf, off + pos)
            pos += c_sizeof(m)


def c_image(t, value):
    buf = bytearray(c_sizeof(t))  # padding stays zero
    c_write(t, value, buf, 0)
    return bytes(buf)


# --- CDR ------------------------------------------------------------------------------------


def cdr_write(t, value, out):
    """Append value to out (the payload after the 4-byte header)."""
    if isinstance(t, str):
        fmt, size = PRIMS[t]
        out.extend(b"\0" * (round_up(len(out), size) - len(out)))
        out.extend(struct.pack("<" + fmt, value))
    elif t[0] == "array":
        for v in value:
            cdr_write(t[1], v, out)
    else:
        for name, m in t[2]:
            cdr_write(m, value[name], out)


def cdr_sample(t, value):
    payload = bytearray()
    cdr_write(t, value, payload)
    return bytes([0x00, 0x01, 0x00, 0x00]) + bytes(payload)


# --- CRC ------------------------------------------------------------------------------------


def crc32_words(words):
    crc = 0xFFFFFFFF
    for word in words:
        for bit in range(31, -1, -1):
            top = (crc >> 31) ^ ((word >> bit) & 1)
            crc = (crc << 1) & 0xFFFFFFFF
            if top:
                crc ^= 0x04C11DB7
    return crc


def image_crc(image):
    n = len(image) // 4 - 1
    return crc32_words(struct.unpack_from("<%dI" % n, image))


# --- Values ---------------------------------------------------------------------------------


def normalize(t, v, path):
    """The value of type t with defaults filled in; errors name the field."""
    if isinstance(t, str):
        if v is None:
            return 0
        if t == "f32":
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ValueError("%s: expected a number, got %r" % (path, v))
            return float(v)
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError("%s: expected an integer, got %r" % (path, v))
        return v
    if t[0] == "array":
        v = [] if v is None else v
        if not isinstance(v, list) or len(v) > t[2]:
            raise ValueError("%s: expected a list of at most %d items" % (path, t[2]))
        return [normalize(t[1], v[i] if i < len(v) else None, "%s[%d]" % (path, i))
                for i in range(t[2])]
    v = {} if v is None else v
    if not isinstance(v, dict):
        raise ValueError("%s: expected an object" % path)
    names = [name for name, _ in t[2]]
    unknown = sorted(set(v) - set(names))
    if unknown:
        raise ValueError("%s: unknown fields %s (%s has %s)" % (path, unknown, t[1], names))
    return {name: normalize(m, v.get(name), "%s.%s" % (path, name)) for name, m in t[2]}


def describe(doc, seal=False):
    if not isinstance(doc, dict) or doc.get("type") not in TYPES:
        raise ValueError('expected {"type": "LowCmd_" or "LowState_", ...}')
    fields = dict(doc)
    name = fields.pop("type")
    t, size = TYPES[name]
    value = normalize(t, fields, name)
    image = c_image(t, value)
    if len(image) != size:
        raise AssertionError("sizeof(%s) = %d, expected %d" % (name, len(image), size))
    crc = image_crc(image)
    if seal:
        value["crc"] = crc
        image = c_image(t, value)
    cdr = cdr_sample(t, value)
    return {
        "type": name,
        "image_size": len(image),
        "crc": crc,
        "image_hex": image.hex(),
        "cdr_size": len(cdr),
        "cdr_hex": cdr.hex(),
    }


def main(argv):
    args = argv[1:]
    seal = "--seal" in args
    args = [a for a in args if a != "--seal"]
    if len(args) > 1 or any(a.startswith("-") for a in args):
        sys.stderr.write(__doc__)
        return 2
    text = args[0] if args else sys.stdin.read()
    try:
        out = describe(json.loads(text), seal)
    except (ValueError, OverflowError, struct.error) as e:
        sys.stderr.write("unitree_crc.py: %s\n" % e)
        return 1
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
