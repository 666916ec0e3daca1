"""Sim-to-real pieces (:mod:`mjx_arm.sim2real`): adapter, limiter, frame check, command output.

The position-controlled envs and ``deploy-sim`` are tested in ``test_deploy_sim.py``.
"""

from __future__ import annotations

import importlib.util
import logging
import math
import re
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mjx_arm.arm.info import arm_info
from mjx_arm.sim2real import (
    FrameAlignmentError,
    JointLimits,
    LimiterConfig,
    Pose,
    SafetyLimiter,
    ServojConfig,
    UnsafeCommandError,
    VelocityToPositionAdapter,
    check_frame_alignment,
    joint_trajectory_msg,
    servoj_line,
    urscript_program,
)
from mjx_arm.sim2real.limiter import stopping_speed

CTRL_DT = 1.0 / 30.0
HOME = np.array([0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])
# Rounding allowance of the limiter's guarantees: relative, plus an absolute floor.
RTOL, ATOL = 1e-9, 1e-9

# --------------------------------------------------------------------------- adapter


def _time_to_63_percent(dt: float, tau: float, jump: float = 0.3) -> float:
    """Time (s) for the adapter's target to cover 1 - 1/e of a jump of the raw target, by
    linear interpolation between control periods. The jump is one period of velocity."""
    adapter = VelocityToPositionAdapter(dt, tau, np.zeros(1))
    level = jump * (1.0 - math.exp(-1.0))
    previous, t = 0.0, 0.0
    qdot = np.array([jump / dt])
    while True:
        y = float(adapter.step(qdot)[0])
        qdot = np.zeros(1)
        t += dt
        if y >= level:
            return t - dt + dt * (level - previous) / (y - previous)
        previous = y


@pytest.mark.parametrize("tau", [0.02, 0.05, 0.2])
def test_adapter_step_response_has_time_constant_tau(tau: float):
    """The filtered target reaches 63.2% of a step after tau (within 5%), at 1 kHz."""
    measured = _time_to_63_percent(1e-3, tau)
    assert measured == pytest.approx(tau, rel=0.05)


@pytest.mark.parametrize("tau", [0.02, 0.05, 0.1])
def test_adapter_step_response_at_the_control_rate(tau: float):
    """At 30 Hz the samples lie on 1 - exp(-t / tau): tau fitted from them within 5%."""
    adapter = VelocityToPositionAdapter(CTRL_DT, tau, np.zeros(1))
    y = [adapter.step(np.array([1.0 / CTRL_DT]))[0]]  # the raw target jumps by 1 rad
    y += [adapter.step(np.zeros(1))[0] for _ in range(5)]
    t = CTRL_DT * np.arange(1, 7)
    fitted = -t / np.log(1.0 - np.array(y))
    np.testing.assert_allclose(fitted, tau, rtol=0.05)


def test_adapter_starts_at_the_measured_position_and_ramps():
    q0 = HOME + 0.1
    adapter = VelocityToPositionAdapter(1e-3, 0.05, q0)
    np.testing.assert_array_equal(adapter.target, q0)
    v = np.array([0.5, -0.5, 1.0, 0.0, 0.2, -1.0])
    for _ in range(1000):  # 1 s, 20 time constants: the lag has settled to v * tau
        target = adapter.step(v)
    raw = q0 + v * 1.0
    np.testing.assert_allclose(adapter.raw_target, raw, atol=1e-9)
    np.testing.assert_allclose(raw - target, v * 0.05, rtol=0.02, atol=1e-12)
    adapter.reset(HOME)
    np.testing.assert_array_equal(adapter.target, HOME)
    np.testing.assert_array_equal(adapter.raw_target, HOME)


def test_adapter_without_filter_integrates_exactly():
    adapter = VelocityToPositionAdapter(0.1, 0.0, np.zeros(2))
    np.testing.assert_allclose(adapter.step(np.array([1.0, -2.0])), [0.1, -0.2], atol=1e-15)


def test_adapter_bounds_stop_wind_up():
    """Pushed into a bound, the raw target stops there: backing out starts at once."""
    adapter = VelocityToPositionAdapter(0.1, 0.0, np.zeros(1), np.array([-1.0]), np.array([1.0]))
    for _ in range(100):
        adapter.step(np.array([1.0]))
    assert adapter.target[0] == 1.0
    assert adapter.step(np.array([-1.0]))[0] == pytest.approx(0.9)


def test_adapter_rejects_bad_input():
    adapter = VelocityToPositionAdapter(0.1, 0.05, np.zeros(6))
    with pytest.raises(ValueError, match="NaN or inf"):
        adapter.step(np.array([0, 0, np.nan, 0, 0, 0]))
    with pytest.raises(ValueError, match="shape"):
        adapter.step(np.zeros(5))
    with pytest.raises(ValueError, match="tau"):
        VelocityToPositionAdapter(0.1, -1.0, np.zeros(6))
    with pytest.raises(ValueError, match="finite"):
        adapter.reset(np.full(6, np.inf))


# --------------------------------------------------------------------------- limiter


def _arm_limits(acceleration: float = 40.0) -> JointLimits:
    return JointLimits.from_urdf(None, LimiterConfig(acceleration=acceleration))


def _assert_within(limits: JointLimits, dt: float, q0: np.ndarray, commands: np.ndarray) -> None:
    """Every command in the band, its velocity and acceleration within the limits."""
    assert (commands >= limits.lower).all() and (commands <= limits.upper).all()
    q = np.vstack([q0, commands])
    v = np.vstack([np.zeros_like(q0), np.diff(q, axis=0) / dt])
    a = np.diff(v, axis=0) / dt
    assert (np.abs(v) <= limits.velocity * (1 + RTOL) + ATOL).all(), np.abs(v).max(axis=0)
    assert (np.abs(a) <= limits.acceleration * (1 + RTOL) + ATOL / dt).all(), np.abs(a).max()


def _run(limiter: SafetyLimiter, targets: np.ndarray) -> np.ndarray:
    return np.array([limiter(t) for t in targets])


def test_limiter_band_comes_from_the_urdf_with_a_margin():
    arm = arm_info()
    limits = JointLimits.from_urdf(None, LimiterConfig(position_margin=0.1, velocity_scale=0.5))
    assert limits.names == arm.joint_names
    np.testing.assert_allclose(limits.lower, arm.lower + 0.1)
    np.testing.assert_allclose(limits.upper, arm.upper - 0.1)
    np.testing.assert_allclose(limits.velocity, arm.v_max * 0.5)
    elbow = arm.joint_names.index("elbow_joint")
    assert limits.upper[elbow] == pytest.approx(math.pi - 0.1)


def test_limiter_passes_feasible_targets_unchanged():
    limits = _arm_limits()
    limiter = SafetyLimiter(limits, CTRL_DT, HOME)
    t = CTRL_DT * np.arange(1, 91)[:, None]
    phase = np.arange(6.0)
    targets = HOME + 0.3 * (np.sin(2.0 * t + phase) - np.sin(phase))  # |v| <= 0.6, |a| <= 1.2
    np.testing.assert_array_equal(_run(limiter, targets), targets)
    assert limiter.total_clips == 0


targets_strategy = st.lists(
    st.lists(
        st.one_of(
            st.floats(-1e6, 1e6, allow_nan=False),
            st.floats(-8.0, 8.0, allow_nan=False),
            st.sampled_from([-1e300, 1e300, -7.0, 7.0, 0.0]),
        ),
        min_size=6,
        max_size=6,
    ),
    min_size=1,
    max_size=60,
)


@settings(max_examples=150, deadline=None)
@given(targets=targets_strategy, start=st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6))
def test_limiter_never_emits_outside_the_arm_limits(targets, start):
    """Random and extreme targets (1e300, far outside the band, jumps) on the shipped arm."""
    limits = _arm_limits()
    q0 = HOME + np.array(start)
    limiter = SafetyLimiter(limits, CTRL_DT, q0)
    _assert_within(limits, CTRL_DT, q0, _run(limiter, np.array(targets)))


@st.composite
def random_limits(draw) -> tuple[JointLimits, float, np.ndarray]:
    """Limits of 1-6 joints, a period and a start inside the band."""
    n = draw(st.integers(1, 6))
    finite = {"allow_nan": False, "allow_infinity": False}
    lower = np.array(draw(st.lists(st.floats(-10, 10, **finite), min_size=n, max_size=n)))
    width = np.array(draw(st.lists(st.floats(1e-3, 10, **finite), min_size=n, max_size=n)))
    velocity = np.array(draw(st.lists(st.floats(1e-2, 10, **finite), min_size=n, max_size=n)))
    accel = np.array(draw(st.lists(st.floats(1e-1, 1e3, **finite), min_size=n, max_size=n)))
    dt = draw(st.sampled_from([1e-3, 2e-3, 1 / 125, 1 / 30, 0.1]))
    share = np.array(draw(st.lists(st.floats(0, 1), min_size=n, max_size=n)))
    names = tuple(f"j{i}" for i in range(n))
    limits = JointLimits(names, lower, lower + width, velocity, accel)
    return limits, dt, np.clip(lower + share * width, limits.lower, limits.upper)


@settings(max_examples=150, deadline=None)
@given(setup=random_limits(), data=st.data())
def test_limiter_never_emits_outside_random_limits(setup, data):
    """Any limits and period; targets random, bang-bang between far ends, or chasing."""
    limits, dt, q0 = setup
    n = len(limits.names)
    steps = data.draw(st.integers(1, 80))
    kind = data.draw(st.sampled_from(["random", "bang-bang", "beyond"]))
    low, high = limits.lower - 5.0, limits.upper + 5.0
    if kind == "random":
        u = np.array(data.draw(st.lists(st.floats(0, 1), min_size=steps * n, max_size=steps * n)))
        targets = low + u.reshape(steps, n) * (high - low)
    elif kind == "bang-bang":
        flips = data.draw(st.lists(st.booleans(), min_size=steps, max_size=steps))
        targets = np.array([high if f else low for f in flips])
    else:  # a target stuck just beyond one end of the band
        targets = np.tile(limits.upper + 1e-3, (steps, 1))
    limiter = SafetyLimiter(limits, dt, q0)
    _assert_within(limits, dt, q0, _run(limiter, targets))


def test_limiter_brakes_before_a_limit():
    """Rushing at a limit, the command stops at it without exceeding the deceleration."""
    limits = JointLimits(("j",), [-1.0], [1.0], [3.0], [10.0])
    limiter = SafetyLimiter(limits, 0.01, np.zeros(1))
    commands = _run(limiter, np.full((300, 1), 5.0))
    _assert_within(limits, 0.01, np.zeros(1), commands)
    assert commands[-1, 0] == pytest.approx(1.0, abs=1e-9)
    assert limiter.velocity[0] == pytest.approx(0.0, abs=1e-6)
    assert limiter.clips[("j", "position")] == 300


def test_limiter_catches_up_without_overshoot():
    """After an acceleration clip the command closes on a step target monotonically."""
    limits = JointLimits(("j",), [-5.0], [5.0], [3.0], [20.0])
    limiter = SafetyLimiter(limits, CTRL_DT, np.zeros(1))
    commands = _run(limiter, np.full((60, 1), 1.0))[:, 0]
    assert (np.diff(commands) >= -1e-12).all()
    assert commands.max() <= 1.0 + 1e-12
    assert commands[-1] == pytest.approx(1.0, abs=1e-9)
    assert limiter.clips[("j", "acceleration")] > 0


def test_limiter_follows_a_moving_target_after_a_clip():
    """A ramp started with a jump: the command catches the ramp and then rides on it."""
    limits = JointLimits(("j",), [-10.0], [10.0], [3.0], [40.0])
    limiter = SafetyLimiter(limits, CTRL_DT, np.zeros(1))
    ramp = 0.5 + 1.0 * CTRL_DT * np.arange(1, 91)  # 0.5 rad ahead, then 1 rad/s
    commands = _run(limiter, ramp[:, None])[:, 0]
    assert (commands <= ramp + 1e-12).all()
    np.testing.assert_allclose(commands[-30:], ramp[-30:], atol=1e-9)


def test_limiter_counts_and_logs_clips_by_joint(caplog):
    limits = _arm_limits()
    limiter = SafetyLimiter(limits, CTRL_DT, HOME)
    target = HOME.copy()
    target[limits.names.index("wrist_2_joint")] += 1.0  # 30 rad/s: over every limit at once
    with caplog.at_level(logging.INFO, logger="mjx_arm.sim2real.limiter"):
        limiter(target)
    assert limiter.clip_summary() == {"wrist_2_joint": {"acceleration": 1}}
    assert "acceleration clip on wrist_2_joint" in caplog.text
    beyond = HOME.copy()
    beyond[limits.names.index("elbow_joint")] = 4.0  # outside the elbow's band
    limiter(beyond)
    assert limiter.clips[("elbow_joint", "position")] == 1
    assert limiter.total_clips == 3  # wrist_2 is still catching up on the first target
    limiter.clear_counts()
    assert limiter.total_clips == 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_limiter_rejects_non_finite_targets(bad: float):
    limits = _arm_limits()
    limiter = SafetyLimiter(limits, CTRL_DT, HOME)
    limiter(HOME + 0.01)
    before, velocity = limiter.command, limiter.velocity
    target = HOME.copy()
    target[limits.names.index("shoulder_lift_joint")] = bad
    with pytest.raises(UnsafeCommandError, match=r"non-finite value for shoulder_lift_joint"):
        limiter(target)
    np.testing.assert_array_equal(limiter.command, before)  # state untouched
    np.testing.assert_array_equal(limiter.velocity, velocity)


def test_limiter_rejects_a_start_outside_its_band_and_wrong_shapes():
    limits = _arm_limits()
    start = HOME.copy()
    start[limits.names.index("elbow_joint")] = math.pi - 0.01  # inside the URDF, in the margin
    with pytest.raises(UnsafeCommandError, match=r"elbow_joint at 3\.1316 rad"):
        SafetyLimiter(limits, CTRL_DT, start)
    with pytest.raises(UnsafeCommandError, match="shape"):
        SafetyLimiter(limits, CTRL_DT, HOME)(np.zeros(5))


def test_stopping_speed_stops_within_the_distance():
    """Braking from the stopping speed by a * dt per period covers at most the distance."""
    for distance, a, dt in [(0.5, 10.0, 0.01), (1e-4, 40.0, 1 / 30), (3.0, 1.0, 0.1)]:
        v = float(stopping_speed(np.array(distance), np.array(a), dt))
        travelled = 0.0
        while v > 0:
            travelled += v * dt
            v -= a * dt
        assert travelled <= distance * (1 + 1e-12)


# --------------------------------------------------------------------------- frames


def test_frame_check_passes_an_exact_match():
    pose = Pose.from_wxyz([0.1, -0.2, 0.3], [math.cos(0.2), 0.0, 0.0, math.sin(0.2)])
    report = check_frame_alignment(pose, pose)
    assert report.ok
    assert report.translation_error == 0.0 and report.rotation_error < 1e-12


def test_frame_check_catches_a_90_degree_yaw():
    s = math.sqrt(0.5)
    robot = {"translation": {"x": 0, "y": 0, "z": 0}, "rotation": {"x": 0, "y": 0, "z": s, "w": s}}
    with pytest.raises(FrameAlignmentError, match=r"yaw \(about z\) off by \+90\.00 deg") as info:
        check_frame_alignment([0, 0, 0, 0, 0, 0, 1], robot)
    assert "roll" not in str(info.value) and "pitch" not in str(info.value)
    report = check_frame_alignment([0, 0, 0, 0, 0, 0, 1], robot, raise_on_failure=False)
    assert report.rotation_error == pytest.approx(math.pi / 2, abs=1e-12)
    assert report.translation_ok and not report.rotation_ok


def test_frame_check_catches_a_30_cm_offset():
    sim = [0, 0, 0, 0, 0, 0, 1]
    with pytest.raises(FrameAlignmentError, match=r"x off by \+0\.3000 m") as info:
        check_frame_alignment(sim, [0.3, 0, 0, 0, 0, 0, 1])
    assert "y off" not in str(info.value) and "rotation error 0.00 deg" in str(info.value)
    report = check_frame_alignment(sim, [0, -0.3, 0, 0, 0, 0, 1], raise_on_failure=False)
    assert report.translation == pytest.approx([0, -0.3, 0])
    assert "y off by -0.3000 m" in report.message()


def test_frame_check_tolerances_and_quaternion_sign():
    sim = Pose(np.zeros(3), [0, 0, 0, 1])
    angle = 0.005  # rad, about y
    tilted = ([0.003, 0, 0.002], [0, -math.sin(angle / 2), 0, -math.cos(angle / 2)])  # -q
    report = check_frame_alignment(sim, tilted, tol_m=0.005, tol_rad=0.01)
    assert report.ok
    assert report.rotation_error == pytest.approx(angle, rel=1e-9)
    with pytest.raises(FrameAlignmentError, match="pitch"):
        check_frame_alignment(sim, tilted, tol_m=0.005, tol_rad=0.004)


# --------------------------------------------------------------------------- commands

SERVOJ = re.compile(r"^servoj\(\[(-?\d+\.\d{6}, ){5}-?\d+\.\d{6}\], 0, 0, 0\.033333, 0\.1, 300\)$")


def test_urscript_streams_servoj_lines():
    names = arm_info().joint_names
    targets = HOME + np.linspace(0, 0.1, 4)[:, None]
    config = ServojConfig(t=CTRL_DT)
    program = urscript_program(targets, config, names)
    lines = program.splitlines()
    assert lines[0] == "def mjx_arm_servo():" and lines[-2:] == ["end", "mjx_arm_servo()"]
    calls = [line.strip() for line in lines if line.strip().startswith("servoj")]
    assert len(calls) == 4 and all(SERVOJ.match(c) for c in calls)
    parsed = [[float(v) for v in c[8 : c.index("]")].split(",")] for c in calls]
    np.testing.assert_allclose(parsed, targets, atol=5e-7)
    assert lines[-3].strip() == "stopj(4)"
    assert servoj_line(HOME, config) == calls[0]
    with pytest.raises(ValueError, match="NaN"):
        urscript_program(np.full((1, 6), np.nan), config, names)
    with pytest.raises(ValueError, match="lookahead_time"):
        ServojConfig(t=CTRL_DT, lookahead_time=0.5)
    with pytest.raises(ValueError, match="gain"):
        ServojConfig(t=CTRL_DT, gain=50)


def test_joint_trajectory_message_shape():
    names = arm_info().joint_names
    targets, velocities = np.tile(HOME, (31, 1)), np.zeros((31, 6))
    msg = joint_trajectory_msg(targets, CTRL_DT, names, velocities, stamp=12.25)
    assert msg["header"] == {"stamp": {"sec": 12, "nanosec": 250_000_000}, "frame_id": "base_link"}
    assert msg["joint_names"] == list(names)
    assert len(msg["points"]) == 31
    first, last = msg["points"][0], msg["points"][-1]
    assert first["time_from_start"] == {"sec": 0, "nanosec": 33_333_333}
    assert last["time_from_start"] == {"sec": 1, "nanosec": 33_333_333}
    assert first["positions"] == pytest.approx(HOME.tolist()) and first["velocities"] == [0.0] * 6
    assert set(first) == {"positions", "velocities", "accelerations", "effort", "time_from_start"}
    assert joint_trajectory_msg(targets, CTRL_DT, names)["points"][0]["velocities"] == []
    with pytest.raises(ValueError, match="shape"):
        joint_trajectory_msg(np.zeros((3, 5)), CTRL_DT, names)


# --------------------------------------------------------------------------- ROS 2 node

HAVE_RCLPY = importlib.util.find_spec("rclpy") is not None


def test_package_imports_without_rclpy():
    code = (
        "import sys; sys.modules['rclpy'] = None\n"  # make `import rclpy` fail
        "import mjx_arm.sim2real\n"
        "heavy = ('mujoco', 'pybullet', 'jax', 'rclpy')\n"
        "assert not [m for m in heavy if sys.modules.get(m) is not None]\n"
        "try:\n"
        "    import mjx_arm.sim2real.ros2_node\n"
        "except ImportError as exc:\n"
        "    print(exc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "needs rclpy" in out.stdout


@pytest.mark.skipif(HAVE_RCLPY, reason="rclpy is installed here")
def test_ros2_node_module_says_it_needs_rclpy():
    with pytest.raises(ImportError, match="needs rclpy"):
        import mjx_arm.sim2real.ros2_node  # noqa: F401
