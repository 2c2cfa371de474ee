"""The controller's RTDE registers: the general-purpose input and output registers (int,
double, bit), which connection writes which input, and the value of every other RTDE output
variable as the robot's state gives it."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from aptkt.errors import UnknownNameError
from aptkt.sim.loopback.config import ROBOT_MODE_POWER_OFF, SAFETY_NORMAL
from aptkt.sim.loopback.rtde import input_type, output_type
from aptkt.sim.physics import GRAVITY

__all__ = ["RtdeRegisters", "RobotState", "output_values"]

_HOME_Q = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)
#: An output variable the controller does not simulate reads as zero of its wire type.
_ZERO: Mapping[str, Any] = {
    "VECTOR3D": [0.0] * 3,
    "VECTOR6D": [0.0] * 6,
    "VECTOR6INT32": [0] * 6,
    "VECTOR6UINT32": [0] * 6,
    "DOUBLE": 0.0,
    "BOOL": False,
}


class RtdeRegisters:
    """48 int and double registers and 128 bits each way, the external wrench input, and the
    owner (connection) of each input variable."""

    def __init__(self) -> None:
        self.input_int = [0] * 48
        self.input_double = [0.0] * 48
        self.output_int = [0] * 48
        self.output_double = [0.0] * 48
        self.input_bits = [False] * 128
        self.output_bits = [False] * 128
        self.external_force_torque = [0.0] * 6
        self._owner: dict[str, int] = {}

    def claim(self, conn_id: int, names: Sequence[str]) -> list[str]:
        """Types for an input recipe; a variable another connection writes is ``IN_USE``."""
        types = []
        for name in names:
            t = input_type(name)
            if t is None:
                types.append("NOT_FOUND")
            elif self._owner.get(name, conn_id) != conn_id:
                types.append("IN_USE")
            else:
                types.append(t)
        if all(t not in ("NOT_FOUND", "IN_USE") for t in types):
            for name in names:
                self._owner[name] = conn_id
        return types

    def release(self, conn_id: int) -> None:
        for name in [n for n, owner in self._owner.items() if owner == conn_id]:
            del self._owner[name]

    def apply(self, values: Mapping[str, Any]) -> None:
        """An input data package."""
        for name, value in values.items():
            if name.startswith("input_int_register_"):
                self.input_int[_index(name)] = int(value)
            elif name.startswith("input_double_register_"):
                self.input_double[_index(name)] = float(value)
            elif name.startswith("input_bit_register_"):
                self.input_bits[_index(name)] = bool(value)
            elif name == "external_force_torque":
                self.external_force_torque = [float(v) for v in value]

    def value(self, name: str) -> Any:
        """A register's value; KeyError for a variable that is not a register."""
        for prefix, registers in (
            ("output_int_register_", self.output_int),
            ("output_double_register_", self.output_double),
            ("input_int_register_", self.input_int),
            ("input_double_register_", self.input_double),
            ("output_bit_register_", self.output_bits),
            ("input_bit_register_", self.input_bits),
        ):
            if name.startswith(prefix):
                return registers[_index(name)]
        raise UnknownNameError(name)


def _index(name: str) -> int:
    return int(name.rsplit("_", 1)[1])


class RobotState(Protocol):
    """What the RTDE outputs other than the registers report."""

    time: float
    pose: np.ndarray
    velocity: np.ndarray
    tcp_force: np.ndarray
    ft_offset: np.ndarray
    robot_mode: int
    safety_mode: int
    runtime_state: int
    payload: tuple[float, list[float]]

    @property
    def program_running(self) -> bool: ...

    @property
    def protective_stopped(self) -> bool: ...


def output_values(registers: RtdeRegisters, robot: RobotState, names: Iterable[str]) -> list[Any]:
    """The values of an output recipe's variables now."""
    table: dict[str, Any] | None = None
    out = []
    for name in names:
        try:
            out.append(registers.value(name))
            continue
        except KeyError:
            pass
        if table is None:
            table = _state_table(robot)
        out.append(table[name] if name in table else _ZERO.get(output_type(name) or "", 0))
    return out


def _state_table(robot: RobotState) -> dict[str, Any]:
    running = robot.program_running
    power = robot.robot_mode != ROBOT_MODE_POWER_OFF
    return {
        "timestamp": robot.time,
        "actual_TCP_pose": robot.pose.tolist(),
        "target_TCP_pose": robot.pose.tolist(),
        "actual_TCP_speed": robot.velocity.tolist(),
        "target_TCP_speed": robot.velocity.tolist(),
        "actual_TCP_force": robot.tcp_force.tolist(),
        "ft_raw_wrench": (robot.tcp_force + robot.ft_offset).tolist(),
        "tcp_force_scalar": float(np.linalg.norm(robot.tcp_force[:3])),
        "robot_mode": robot.robot_mode,
        "safety_mode": robot.safety_mode,
        "safety_status": robot.safety_mode,
        "runtime_state": robot.runtime_state,
        "robot_status_bits": (1 if power else 0) | (2 if running else 0),
        "safety_status_bits": (1 if robot.safety_mode == SAFETY_NORMAL else 0)
        | (4 if robot.protective_stopped else 0),
        "joint_mode": [253] * 6,
        "speed_scaling": 1.0,
        "target_speed_fraction": 1.0,
        "actual_tool_accelerometer": [0.0, 0.0, -GRAVITY],
        "joint_temperatures": [30.0] * 6,
        "actual_main_voltage": 48.0,
        "actual_robot_voltage": 48.0,
        "actual_joint_voltage": [48.0] * 6,
        "actual_execution_time": 0.5,
        "payload": robot.payload[0],
        "payload_cog": list(robot.payload[1]),
        "target_q": list(_HOME_Q),
        "actual_q": list(_HOME_Q),
    }
