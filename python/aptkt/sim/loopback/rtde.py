"""The RTDE wire format (protocol version 2) as the controller side speaks it.

Facts from Universal Robots' public RTDE guide: every package is ``uint16 size`` (header
included, big-endian) + ``uint8 type`` + payload; all numbers are big-endian. Variable names
and their wire types are the controller's; ur_rtde parses data packages with its own type
table, so the types here must match the controller's exactly or the client misreads every
field after the first mismatch.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence

__all__ = [
    "HEADER",
    "REQUEST_PROTOCOL_VERSION",
    "GET_URCONTROL_VERSION",
    "TEXT_MESSAGE",
    "DATA_PACKAGE",
    "SETUP_OUTPUTS",
    "SETUP_INPUTS",
    "START",
    "PAUSE",
    "output_type",
    "input_type",
    "Recipe",
    "pack",
]

HEADER = struct.Struct(">HB")

REQUEST_PROTOCOL_VERSION = ord("V")
GET_URCONTROL_VERSION = ord("v")
TEXT_MESSAGE = ord("M")
DATA_PACKAGE = ord("U")
SETUP_OUTPUTS = ord("O")
SETUP_INPUTS = ord("I")
START = ord("S")
PAUSE = ord("P")

#: struct format of each RTDE wire type.
TYPE_FORMAT: dict[str, str] = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}

_FIXED_OUTPUTS: dict[str, str] = {
    "timestamp": "DOUBLE",
    "target_q": "VECTOR6D",
    "target_qd": "VECTOR6D",
    "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D",
    "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D",
    "actual_current": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D",
    "actual_TCP_speed": "VECTOR6D",
    "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D",
    "target_TCP_speed": "VECTOR6D",
    "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32",
    "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D",
    "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE",
    "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE",
    "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D",
    "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE",
    "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE",
    "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32",
    "tool_output_current": "DOUBLE",
    "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32",
    "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32",
    "input_bit_registers32_to_63": "UINT32",
    "ft_raw_wrench": "VECTOR6D",
    "payload": "DOUBLE",
    "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D",
    "script_control_line": "UINT32",
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
}

# Variables a client may write (SETUP_INPUTS) besides the general purpose registers.
_FIXED_INPUTS: dict[str, str] = {
    "external_force_torque": "VECTOR6D",
    "speed_slider_mask": "UINT32",
    "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8",
    "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8",
    "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE",
    "standard_analog_output_1": "DOUBLE",
}

_REGISTER = re.compile(r"^(input|output)_(int|double|bit)_register_(\d+)$")


def _register_type(name: str) -> tuple[str, str] | None:
    """(direction, wire type) of a general purpose register name, or None."""
    m = _REGISTER.match(name)
    if not m:
        return None
    direction, kind, index = m.group(1), m.group(2), int(m.group(3))
    if kind == "bit":
        # Bit registers 0..63 are the PLC range; 64..127 are the general purpose ones.
        return (direction, "BOOL") if 64 <= index <= 127 else None
    if not 0 <= index <= 47:
        return None
    return direction, ("INT32" if kind == "int" else "DOUBLE")


def output_type(name: str) -> str | None:
    """Wire type of a variable the controller can send, or None if it does not exist.

    Input registers are readable as outputs too (the controller echoes them).
    """
    reg = _register_type(name)
    if reg is not None:
        return reg[1]
    return _FIXED_OUTPUTS.get(name)


def input_type(name: str) -> str | None:
    """Wire type of a variable a client may write, or None if it cannot be written."""
    reg = _register_type(name)
    if reg is not None:
        return reg[1] if reg[0] == "input" else None
    return _FIXED_INPUTS.get(name)


class Recipe:
    """An output or input recipe: names, wire types and the compiled struct of one package."""

    def __init__(
        self, recipe_id: int, names: Sequence[str], types: Sequence[str], frequency: float = 0.0
    ):
        self.id = recipe_id
        self.names = list(names)
        self.types = list(types)
        self.frequency = frequency
        self.struct = struct.Struct(">B" + "".join(TYPE_FORMAT[t] for t in types))

    def encode(self, values: Sequence[object]) -> bytes:
        """Pack one data package (header included) from one value per variable."""
        flat: list[object] = [self.id]
        for t, v in zip(self.types, values):
            if t.startswith("VECTOR"):
                flat.extend(v)  # type: ignore[arg-type]
            else:
                flat.append(v)
        body = self.struct.pack(*flat)
        return HEADER.pack(HEADER.size + len(body), DATA_PACKAGE) + body

    def decode(self, payload: bytes) -> dict[str, object]:
        """Unpack a data package payload (recipe id byte included) into name -> value."""
        flat = self.struct.unpack(payload[: self.struct.size])
        out: dict[str, object] = {}
        i = 1
        for name, t in zip(self.names, self.types):
            n = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}.get(t, 1)
            out[name] = flat[i] if n == 1 else list(flat[i : i + n])
            i += n
        return out


def pack(kind: int, payload: bytes = b"") -> bytes:
    """One complete package: header + payload."""
    return HEADER.pack(HEADER.size + len(payload), kind) + payload
