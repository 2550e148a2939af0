"""The channel contract of upc (services/CHANNELS.md) for Python participants.

ctypes mirrors of the `#[repr(C)]` payloads of src/channels/messages.rs, their constants, the
service settings every upc process opens its iceoryx2 services with (src/channels/node.rs: a
participant opened with other settings cannot join), and the framing of the same payloads on
Zenoh (src/bridge/wire.rs). iceoryx2 is imported only by the iceoryx2 helpers: a participant on
another host, over Zenoh, needs only ctypes.
"""

import ctypes
import struct

MAX_DOF = 128
N_CONTACTS = 8
MAX_FORECAST = 2048
SCENARIO_NAME_LEN = 128

STATE_FLAG_HOLD = 1
STATE_FLAG_LOCKSTEP = 2
STATE_FLAG_DAMPING = 4
STATE_FLAG_BASE_UNMEASURED = 8
TORQUE_FLAG_FALLBACK = 1


class StateMsg(ctypes.Structure):
    _fields_ = [
        ("step", ctypes.c_uint64),
        ("time", ctypes.c_double),
        ("nq", ctypes.c_uint32),
        ("nv", ctypes.c_uint32),
        ("q", ctypes.c_double * MAX_DOF),
        ("v", ctypes.c_double * MAX_DOF),
        ("contact_forces", (ctypes.c_double * 3) * N_CONTACTS),
        ("zmp", ctypes.c_double * 2),
        ("door_angle", ctypes.c_double),
        ("door_velocity", ctypes.c_double),
        ("hand_force", ctypes.c_double * 3),
        ("session", ctypes.c_uint64),
        ("scenario_hash", ctypes.c_uint64),
        ("scenario_start", ctypes.c_double),
        ("flags", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("force_scale", ctypes.c_double),
        ("robot_hash", ctypes.c_uint64),
        ("scenario", ctypes.c_uint8 * SCENARIO_NAME_LEN),
        ("imu_orientation", ctypes.c_double * 4),
        ("imu_angular_velocity", ctypes.c_double * 3),
        ("imu_linear_acceleration", ctypes.c_double * 3),
        ("foot_wrenches", (ctypes.c_double * 6) * 2),
        ("stamps", ctypes.c_double * 4),
        ("joint_torques", ctypes.c_double * MAX_DOF),
    ]

    @staticmethod
    def type_name() -> str:
        return "upc::StateMsg"


class TorqueMsg(ctypes.Structure):
    _fields_ = [
        ("seq", ctypes.c_uint64),
        ("state_step", ctypes.c_uint64),
        ("n", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("compute_ns", ctypes.c_uint64),
        ("session", ctypes.c_uint64),
        ("controller", ctypes.c_uint64),
        ("tau", ctypes.c_double * MAX_DOF),
    ]

    @staticmethod
    def type_name() -> str:
        return "upc::TorqueMsg"


class ForecastMsg(ctypes.Structure):
    _fields_ = [
        ("seq", ctypes.c_uint64),
        ("t0", ctypes.c_double),
        ("dt", ctypes.c_double),
        ("len", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("period", ctypes.c_double),
        ("scenario_hash", ctypes.c_uint64),
        ("forces", (ctypes.c_double * 3) * MAX_FORECAST),
    ]

    @staticmethod
    def type_name() -> str:
        return "upc::ForecastMsg"


class GroundTruthMsg(ctypes.Structure):
    _fields_ = [
        ("step", ctypes.c_uint64),
        ("time", ctypes.c_double),
        ("com", ctypes.c_double * 3),
        ("loop_error", ctypes.c_double),
        ("max_penetration", ctypes.c_double),
        ("max_slip_speed", ctypes.c_double),
        ("door_torque", ctypes.c_double),
        ("step_time", ctypes.c_double),
        ("solver_iterations", ctypes.c_uint32),
        ("rejected_commands", ctypes.c_uint32),
        ("stale_commands", ctypes.c_uint64),
        ("flags", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("hold_steps", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "upc::GroundTruthMsg"


# History per service (src/channels/mod.rs): a late subscriber gets the last state and
# forecast; torques and ground truth are only for those listening.
_HISTORY = {"state": 1, "forecast": 1, "torques": 0, "ground_truth": 0}


def pubsub(node, prefix: str, kind: str, payload):
    """The publish–subscribe service `<prefix>/<kind>` with the contract's settings."""
    import iceoryx2 as iox2

    return (
        node.service_builder(iox2.ServiceName.new(f"{prefix}/{kind}"))
        .publish_subscribe(payload)
        .history_size(_HISTORY[kind])
        .subscriber_max_buffer_size(4)
        .enable_safe_overflow(True)
        .max_publishers(4)
        .max_subscribers(8)
        .max_nodes(16)
        .open_or_create()
    )


def event(node, prefix: str, kind: str):
    """The event service `<prefix>/<kind>/event` a publisher notifies after each sample."""
    import iceoryx2 as iox2

    return (
        node.service_builder(iox2.ServiceName.new(f"{prefix}/{kind}/event"))
        .event()
        .max_notifiers(4)
        .max_listeners(8)
        .max_nodes(16)
        .open_or_create()
    )


# Over Zenoh (`upc bridge`): key `<key_prefix>/<kind>`, payload = a 16-byte header (magic
# b"UPCZ", contract version u16, kind u16, payload size u32, reserved u32; little-endian) and
# the payload's bytes as above. The bridge refuses a payload whose header does not match.
WIRE_MAGIC = b"UPCZ"
WIRE_VERSION = 4
_WIRE_KIND = {"state": 1, "torques": 2, "forecast": 3, "ground_truth": 4}
_WIRE_HEADER = struct.Struct("<4sHHII")


class WireError(ValueError):
    """A payload from Zenoh that is not the expected upc message."""


def wire_encode(kind: str, msg) -> bytes:
    """The bytes of `msg` (a payload above) on Zenoh's `<key_prefix>/<kind>`."""
    body = bytes(msg)
    return _WIRE_HEADER.pack(WIRE_MAGIC, WIRE_VERSION, _WIRE_KIND[kind], len(body), 0) + body


def wire_decode(kind: str, payload, cls):
    """The `cls` message in a payload from Zenoh's `<key_prefix>/<kind>`, or WireError."""
    data = bytes(payload)
    if len(data) < _WIRE_HEADER.size or data[:4] != WIRE_MAGIC:
        raise WireError(f"not a upc payload ({len(data)} bytes)")
    _, version, code, size, _ = _WIRE_HEADER.unpack_from(data)
    if version != WIRE_VERSION:
        raise WireError(
            f"the peer speaks contract version {version}, this one {WIRE_VERSION}: run every "
            "participant from the same upc version (services/CHANNELS.md, \"Contract version\")"
        )
    if code != _WIRE_KIND[kind]:
        raise WireError(f"payload kind {code} on the {kind} key")
    body = data[_WIRE_HEADER.size:]
    if size != ctypes.sizeof(cls) or len(body) != size:
        raise WireError(f"{kind} of {len(body)} bytes, expected {ctypes.sizeof(cls)}")
    return cls.from_buffer_copy(body)
