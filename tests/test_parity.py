"""Engine parity: the PyBullet reference env against the CPU MuJoCo env, same contract.

Tolerances are about 1.5-2x what was measured (on the shipped arm, pybullet 3.2.7,
mujoco 4.0.0); each assertion states the measured figure. Run with ``pytest -s`` to see the
figures of this run.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from mjx_arm.bench.engines import MujocoEngine
from mjx_arm.bench.parity import BOX_POSITIONS, random_joint_angles
from mjx_arm.envs.base import BaseRobotEnv
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.task import reach_config, touch_config
from pybullet_ref import PybulletArmEnv

pytestmark = pytest.mark.pybullet

N_CONFIGS = 20
# Open-loop runs: 30 control steps (1 s) of piecewise-constant random actions, held 5 steps.
OPEN_LOOP_SEEDS = (1, 2, 3, 4, 5, 6, 7, 8)  # seed 0 drives the arm into the table: left out
OPEN_LOOP_STEPS, HOLD = 30, 5
# Touch: the press controller (box positions: the parity benchmark's).
PRESS_STEPS, PRESS_AVERAGE = 60, 10  # contact starts at step 48-50
PRESS_DEPTH = 0.01  # the ee is driven this far below the top-face centre (m)
# joint angles (6,) -> the ee position Jacobian (3, 6) of the MuJoCo model
Jacobian = Callable[[np.ndarray], np.ndarray]


def _pair(task) -> tuple[MujocoArmEnv, PybulletArmEnv]:
    return MujocoArmEnv(task), PybulletArmEnv(task)


@pytest.fixture(scope="module")
def reach_pair():
    """MuJoCo and PyBullet envs of Reach that do not end on success."""
    envs = _pair(reach_config(terminate_on_success=False))
    yield envs
    for env in envs:
        env.close()


@pytest.fixture(scope="module")
def touch_pair():
    """MuJoCo and PyBullet envs of Touch that do not end on success.

    The seed variant's joint speed, as in ``mjx-arm bench parity``: the engines are compared at
    the speed the URDF allows, and the tool reaches every box within the press.
    """
    envs = _pair(touch_config("seed", terminate_on_success=False))
    yield envs
    for env in envs:
        env.close()


def _open_loop_actions(seed: int) -> np.ndarray:
    """Piecewise-constant uniform actions in [-1, 1], shape ``(OPEN_LOOP_STEPS, 6)``."""
    rng = np.random.default_rng(1000 + seed)
    levels = rng.uniform(-1.0, 1.0, (OPEN_LOOP_STEPS // HOLD, 6))
    return np.repeat(levels, HOLD, axis=0).astype(np.float32)


def _run_open_loop(env: BaseRobotEnv, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Reset with ``seed``, play the seed's actions.

    Returns:
        Final joint angles (rad) ``(6,)`` and the largest |wrench| component per axis over the
        run, ``(6,)``.
    """
    env.reset(seed=seed)
    peak = np.zeros(6)
    for action in _open_loop_actions(seed):
        env.step(action)
        peak = np.maximum(peak, np.abs(env._reading.wrench))
    return env._reading.qpos.copy(), peak


def _press(env: BaseRobotEnv, jacobian: Jacobian, box: tuple[float, ...]) -> np.ndarray:
    """Drive the ee ``PRESS_DEPTH`` below the box's top-face centre; return the wrench history.

    The same velocity controller for both engines: ``v = lstsq(J, 2 * err)`` with J from the
    MuJoCo model at the engine's joint angles.

    Returns:
        The tared wrench after each control step, shape ``(PRESS_STEPS, 6)``.
    """
    env.reset(seed=0, options={"target": np.array(box)})
    scale = env.task.action_scale * env.arm.v_max
    wrenches = []
    for _ in range(PRESS_STEPS):
        reading = env._reading
        err = reading.target_pos - reading.ee_pos + np.array([0.0, 0.0, -PRESS_DEPTH])
        v = np.linalg.lstsq(jacobian(reading.qpos), 2.0 * err, rcond=None)[0]
        env.step(np.clip(v / scale, -1.0, 1.0).astype(np.float32))
        wrenches.append(env._reading.wrench.copy())
    return np.array(wrenches)


def test_forward_kinematics_agree(reach_pair):
    """ee pose at 20 random joint configurations (joints set directly in both engines)."""
    mj, pb = reach_pair
    position_err, angle_err = [], []
    for qpos in random_joint_angles(mj.arm, N_CONFIGS, seed=0):
        poses = []
        for env in (mj, pb):
            env._physics_reset(qpos, np.array([0.5, 0.0, 0.2]))
            poses.append(env.get_ee_pose())
        (p_mj, q_mj), (p_pb, q_pb) = ((p[:3], p[3:]) for p in poses)
        position_err.append(np.max(np.abs(p_mj - p_pb)))
        dot = min(1.0, abs(float(np.dot(q_mj, q_pb))))
        angle_err.append(2.0 * np.arccos(dot))
    print(f"\n[parity] FK: max |dp| {max(position_err):.2e} m, max angle {max(angle_err):.2e} rad")
    assert max(position_err) < 1e-5  # measured 2.4e-8 m
    assert max(angle_err) < 1e-5  # measured ~2e-7 rad (float precision of the comparison)


def test_open_loop_joint_angles_agree(reach_pair):
    """Same reset, same 1 s of open-loop actions: joint angles and free-motion F/T readings."""
    mj, pb = reach_pair
    diffs, peak_mj, peak_pb = [], np.zeros(6), np.zeros(6)
    for seed in OPEN_LOOP_SEEDS:
        q_mj, w_mj = _run_open_loop(mj, seed)
        q_pb, w_pb = _run_open_loop(pb, seed)
        assert np.max(w_mj[:3]) < 1e-3, f"seed {seed} touches something: pick another seed"
        diffs.append(np.abs(q_mj - q_pb))
        peak_mj, peak_pb = np.maximum(peak_mj, w_mj), np.maximum(peak_pb, w_pb)
    per_joint = np.max(diffs, axis=0)
    print(f"\n[parity] open loop 1 s: max |dq| per joint (rad) {np.round(per_joint, 4).tolist()}")
    print(
        f"[parity] free-motion |F| max: mujoco {peak_mj[:3].max():.2e} N, pybullet "
        f"{peak_pb[:3].max():.3f} N; |tau| max: mujoco {peak_mj[3:].max():.2e} N m, "
        f"pybullet {peak_pb[3:].max():.3f} N m"
    )
    # measured max 0.052 rad (wrist 1, seed 7); per joint 0.013 0.019 0.009 0.052 0.013 0.009
    assert per_joint.max() < 0.08
    # tared F/T in fast free motion: measured pybullet 0.55 N / 0.035 N m, mujoco 4e-12 N /
    # 0.013 N m (its angular-acceleration sensor is world-frame, read as tool-frame)
    for peak in (peak_mj, peak_pb):
        assert peak[:3].max() < 1.0
        assert peak[3:].max() < 0.07


def test_reset_reads_no_contact(touch_pair):
    """Right after reset nothing touches the tool: both F/T readings are about zero."""
    for env in touch_pair:
        obs, _ = env.reset(seed=3)
        assert np.abs(obs["contact_force"]).max() < 1e-3, env.engine


def test_pybullet_ft_convention_at_rest(touch_pair):
    """PyBullet's raw F/T reading, tool hanging at rest: -m g in the tool frame, torque ~0.

    Found: ``getJointState(ft)[2]`` is the force the arm exerts on the tool subtree, in the
    tool link frame, with the torque about the tool link's centre of mass (not the joint).
    """
    _, pb = touch_pair
    tool = pb.arm.tool
    for qpos in ((0.0, -1.57, 1.57, -1.57, -1.57, 0.0), (0.0, -1.57, 1.57, 0.0, 0.0, 0.5)):
        pb._physics_reset(np.array(qpos), np.array([0.5, 0.0, 0.0]))
        reaction = np.array(pb.client.getJointState(pb.body, pb.ids.ft)[2])
        orientation = pb.client.getLinkState(pb.body, pb.ids.ft, computeForwardKinematics=1)[5]
        rot = np.array(pb.client.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        weight = tool.mass * (rot.T @ np.array([0.0, 0.0, -9.81]))
        np.testing.assert_allclose(reaction[:3], -weight, atol=2e-3)
        np.testing.assert_allclose(reaction[3:], 0.0, atol=2e-3)


def test_press_force_agrees(touch_pair):
    """Both engines press the box top with the same commands: same force norm, in the band."""
    mj, pb = touch_pair
    jacobian = MujocoEngine(mj).jacobian
    low, high = mj.task.force_band
    worst = 0.0
    for box in BOX_POSITIONS:
        f_mj, f_pb = (
            float(np.mean(np.linalg.norm(_press(env, jacobian, box)[-PRESS_AVERAGE:, :3], axis=1)))
            for env in (mj, pb)
        )
        relative = abs(f_pb - f_mj) / f_mj
        worst = max(worst, relative)
        print(
            f"\n[parity] press at {box}: mujoco {f_mj:.2f} N, pybullet {f_pb:.2f} N "
            f"({100 * relative:.1f} %)"
        )
        assert low <= f_mj <= high and low <= f_pb <= high
        # measured: 3.5-8.5 % at seven positions, 20.8 % at (0.6, -0.2) (MuJoCo's soft
        # friction lets the tip creep, Bullet's sticks)
        assert relative < 0.35
    print(f"[parity] press: worst relative difference {100 * worst:.1f} %")
