"""The channel contract of upc (services/CHANNELS.md) for Python participants.

ctypes mirrors of the `#[repr(C)]` payloads of src/channels/messages.rs, their constants, and
the service settings every upc process opens its services with (src/channels/bus.rs): a
participant opened with other settings cannot join.
"""

import ctypes

import iceoryx2 as iox2

MAX_DOF = 48
N_CONTACTS = 8
MAX_FORECAST = 2048
SCENARIO_NAME_LEN = 128

STATE_FLAG_HOLD = 1
STATE_FLAG_LOCKSTEP = 2
STATE_FLAG_DAMPING = 4
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
    return (
        node.service_builder(iox2.ServiceName.new(f"{prefix}/{kind}/event"))
        .event()
        .max_notifiers(4)
        .max_listeners(8)
        .max_nodes(16)
        .open_or_create()
    )
