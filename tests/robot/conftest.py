"""Fixtures for the UR10 backend: a loopback controller process and the real ur_rtde client."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from loopback_helpers import (  # tests/helpers (see tests/conftest.py)
    DEFAULT_CONTACT,
    FAST,
    PLACEMENT,
    START_POSE,
    FakeSkin,
    free_loopback_host,
)
from timing import FeedStall, MachineProbe, unless_the_feed_stalled

from aptkt.robot import UR10, SafetyLimits
from aptkt.sim.loopback import Loopback


@pytest.fixture(scope="module")
def loopback() -> Iterator[Loopback]:
    lb = Loopback(
        free_loopback_host(),
        contact=DEFAULT_CONTACT,
        start_pose=START_POSE,
        unlock_delay=0.0,
    )
    with lb:
        yield lb


@pytest.fixture
def skin(loopback: Loopback) -> FakeSkin:
    return FakeSkin(loopback)


@pytest.fixture(scope="module")
def _shared_robot(loopback: Loopback) -> Iterator[dict]:
    holder: dict = {"robot": None}
    yield holder
    if holder["robot"] is not None:
        holder["robot"].close()


@pytest.fixture
def make_robot(loopback: Loopback, _shared_robot: dict) -> Iterator[Callable[..., UR10]]:
    """Factory: a fresh loopback state and a connected UR10 with the given limit overrides."""
    robots: list[UR10] = []
    if _shared_robot["robot"] is not None:
        # The controller gives the command registers to one client at a time (IN_USE).
        _shared_robot["robot"].close()
        _shared_robot["robot"] = None

    def make(
        pose: tuple[float, ...] = START_POSE, contact: dict | None = None, **limits: float
    ) -> UR10:
        while robots:  # (one client at a time: a test's next attempt replaces its robot)
            robots.pop().close()
        loopback.reset(pose=pose)
        loopback.set_contact(contact or DEFAULT_CONTACT)
        robot = UR10(loopback.host, [PLACEMENT], SafetyLimits(**{**FAST, **limits}))
        robots.append(robot)
        return robot

    yield make
    while robots:
        robots.pop().close()


@pytest.fixture
def healthy_robot(loopback: Loopback, _shared_robot: dict) -> Callable[[], UR10]:
    """A connected UR10 at the start pose, reused while it stays healthy (connecting is cheap,
    but ur_rtde's disconnect sleeps 0.5 s per client); a new one after a fault."""

    def get() -> UR10:
        current = _shared_robot["robot"]
        healthy = current is not None and current.connected and loopback.state()["program_running"]
        loopback.reset(pose=START_POSE, keep_program=healthy)
        loopback.set_contact(DEFAULT_CONTACT)
        if not healthy:
            if current is not None:
                current.close()
            loopback.reset(pose=START_POSE)
            current = UR10(loopback.host, [PLACEMENT], SafetyLimits(**FAST))
            _shared_robot["robot"] = current
        return current

    return get


@pytest.fixture
def robot(healthy_robot: Callable[[], UR10]) -> UR10:
    """The shared UR10 at the start pose (:func:`healthy_robot`)."""
    return healthy_robot()


@pytest.fixture(scope="module")
def feed(loopback: Loopback) -> Iterator[FeedStall]:
    """How long the machine kept the controller's watchdog waiting for its feed (a movement's
    supervision, the control client, the controller): a test whose arm the watchdog stopped
    while this exceeded half its period is no evidence, and is repeated
    (:func:`timing.repeat_if_disturbed`)."""
    machine = MachineProbe()
    try:
        yield FeedStall(loopback, machine)
    finally:
        machine.close()


@pytest.fixture
def on_a_healthy_arm(
    loopback: Loopback, healthy_robot: Callable[[], UR10], feed: FeedStall
) -> Callable[..., None]:
    """``on_a_healthy_arm(body)``: ``body(robot, skin)`` — movements under the controller's
    watchdog, and what they must do — on a healthy robot (or ``robot()``, if given) and a new
    skin. During a movement only aptkt's supervision feeds the watchdog; an attempt that failed
    while the machine kept that feed waiting for more than half the watchdog's period is no
    evidence either way and is repeated (:func:`timing.unless_the_feed_stalled`); a failure
    without such a stall fails at once."""

    def run(body: Callable[[UR10, FakeSkin], object], robot: Callable[[], UR10] = healthy_robot):
        unless_the_feed_stalled(
            feed, lambda: body(robot(), FakeSkin(loopback)), SafetyLimits().watchdog_timeout
        )

    return run
