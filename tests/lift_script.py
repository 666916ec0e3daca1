"""A scripted pick for the Lift env of any engine: the ee Jacobian (from the task's MuJoCo model)
turns a Cartesian plan into joint velocity actions."""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_arm.arm.model_io import arm_model
from mjx_arm.task.observation import decode_joints

GAIN = 4.0  # 1/s: Cartesian speed per metre (and rad/s per rad) of error
SPEED = 0.15  # m/s at most
ALIGNED_SPEED = 0.05  # m/s at most with ``align`` before the lift (a straighter path down)
ALIGNED_TURN_WEIGHT = 0.1  # with ``align``: the orientation's weight against the position's
LIMIT_ROOM = 0.02  # rad: with ``align``, a joint this near a limit is at it
ALIGNED_CLOSE_TOL = 0.005  # m: with ``align``, near enough to close (the jaw leaves 1 cm a side)
# with ``align``, the close phase lasts until both pads press this much (N), or this many steps
ALIGNED_GRIP_FORCE, ALIGNED_CLOSE_STEPS = 5.0, 45


class ScriptedLift:
    """Over the cube (``above`` m over its centre), down to 5 mm above its centre, close for
    0.5 s, lift 0.15 m.

    ``align``: first turn the tool about the vertical so that the pads close square to a face
    of the cube (a one-jaw gripper's pads, about 5 cm apart open, do not fit across a 2.7 cm
    cube's diagonal), and move at most :data:`ALIGNED_SPEED` (the servos' lag bends a faster
    path by 5-8 mm, the room the jaws leave beside that cube), and close until both pads press
    (a jaw whose squeeze is capped closes in about a second); off, the tool keeps its home
    orientation (a wide gripper fits either way) and closes for 0.5 s.
    """

    def __init__(self, env, align: bool = False, above: float = 0.06) -> None:
        self.env, self.arm, self.task = env, env.arm, env.task
        self.model = arm_model(env.arm, env.task)
        self.data = mujoco.MjData(self.model)
        self.adr = [self.model.joint(n).qposadr[0] for n in self.arm.joint_names]
        self.dofs = [self.model.joint(n).dofadr[0] for n in self.arm.joint_names]
        self.site = self.model.site("ee").id
        self.phase, self.count, self.cube0 = "above", 0, None
        self.coding = self.arm.joint_coding(self.task)
        self.tool_down = self._home_quat()  # the home pose holds the tool down
        self.align, self.above = align, above

    def _home_quat(self) -> np.ndarray:
        """The ee orientation (w, x, y, z) at the task's home pose."""
        self.data.qpos[self.adr] = self.task.home_qpos
        mujoco.mj_kinematics(self.model, self.data)
        return self.data.xquat[self.model.site_bodyid[self.site]].copy()

    def _aligned(self, obs: dict) -> np.ndarray:
        """The home orientation turned about the vertical (by at most 45 degrees) so that the
        line between the pads' touch sites, at home, is square to a face of the cube."""
        self.data.qpos[self.adr] = self.task.home_qpos
        mujoco.mj_kinematics(self.model, self.data)
        sites = [self.model.site(f"{link}_pad").id for link in self.arm.gripper.pad_links[:2]]
        closing = self.data.site_xpos[sites[0]] - self.data.site_xpos[sites[1]]
        cube = np.zeros(4)
        mujoco.mju_mulQuat(
            cube, obs["ee_pose"][3:].astype(float), obs["object_rel"][3:].astype(float)
        )
        cube_yaw = 2.0 * np.arctan2(cube[3], cube[0])  # the cube turns about z only
        turn = cube_yaw - np.arctan2(closing[1], closing[0])
        turn = (turn + np.pi / 4) % (np.pi / 2) - np.pi / 4  # a face every quarter turn
        about_z, out = np.array([np.cos(turn / 2), 0.0, 0.0, np.sin(turn / 2)]), np.zeros(4)
        mujoco.mju_mulQuat(out, about_z, self.tool_down)
        return out

    def _qdot(self, qpos: np.ndarray, ee: np.ndarray, goal: np.ndarray, quat) -> np.ndarray:
        self.data.qpos[self.adr] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        jacp, jacr = np.zeros((3, self.model.nv)), np.zeros((3, self.model.nv))
        mujoco.mj_jacSite(self.model, self.data, jacp, jacr, self.site)
        jac = np.vstack([jacp[:, self.dofs], jacr[:, self.dofs]])
        v = GAIN * (goal - ee)
        speed = ALIGNED_SPEED if self.align and self.phase != "lift" else SPEED
        v *= min(1.0, speed / max(np.linalg.norm(v), 1e-9))
        error = np.zeros(3)  # rotation from the ee's orientation to tool-down (ee frame)
        mujoco.mju_subQuat(error, self.tool_down, np.asarray(quat, float))
        world = np.zeros(3)
        mujoco.mju_rotVecQuat(world, error, np.asarray(quat, float))
        twist = np.concatenate([v, GAIN * world])
        if not self.align:
            return jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), twist)
        # a 5-joint arm may not turn the tool exactly: the position comes first (alone while
        # lifting), and a joint at its limit is left out where it would push past it
        turn = 0.0 if self.phase == "lift" else ALIGNED_TURN_WEIGHT
        weights = np.array([1.0, 1.0, 1.0, turn, turn, turn])
        jac, twist = jac * weights[:, None], twist * weights
        free = np.ones(len(self.dofs), bool)
        for _ in range(2):
            used = jac * free
            qdot = used.T @ np.linalg.solve(used @ used.T + 1e-6 * np.eye(6), twist)
            low, high = self.arm.lower + LIMIT_ROOM, self.arm.upper - LIMIT_ROOM
            free &= ~(((qpos <= low) & (qdot < 0)) | ((qpos >= high) & (qdot > 0)))
        return qdot

    def __call__(self, obs: dict) -> np.ndarray:
        ee, cube = obs["ee_pose"][:3].astype(float), obs["target_rel"].astype(float)
        if self.cube0 is None:
            self.cube0 = cube.copy()
            if self.align:
                self.tool_down = self._aligned(obs)
        goal, grip = np.add(self.cube0, [0.0, 0.0, self.above]), -1.0
        if self.phase == "above" and np.linalg.norm(goal - ee) < 0.005:
            self.phase = "down"
        if self.phase == "down":
            goal = np.add(self.cube0, [0.0, 0.0, 0.005])
            if np.linalg.norm(goal - ee) < (ALIGNED_CLOSE_TOL if self.align else 0.003):
                self.phase = "close"
        if self.phase == "close":
            goal, grip = np.add(self.cube0, [0.0, 0.0, 0.005]), 1.0
            self.count += 1
            gripped = not self.align or (obs["pad_force"] >= ALIGNED_GRIP_FORCE).all()
            if (self.count >= 15 and gripped) or self.count >= ALIGNED_CLOSE_STEPS:
                self.phase = "lift"
        if self.phase == "lift":
            goal, grip = np.add(self.cube0, [0.0, 0.0, 0.17]), 1.0
        q = decode_joints(obs["joint_angles"].astype(float), self.coding)
        qdot = self._qdot(q, ee, goal, obs["ee_pose"][3:])
        arm = qdot / self.task.joint_speeds(self.arm.v_max)
        return np.clip(np.append(arm, grip), -1.0, 1.0).astype(np.float32)


class OpenHandPress(ScriptedLift):
    """Over the cube, then down past its centre with the gripper held open: the open hand
    comes to rest around the cube on whatever it meets first (the table, for a hand whose
    open fingers straddle the cube)."""

    def __call__(self, obs: dict) -> np.ndarray:
        ee = obs["ee_pose"][:3].astype(float)
        if self.cube0 is None:
            self.cube0 = obs["target_rel"].astype(float).copy()
        goal = np.add(self.cube0, [0.0, 0.0, self.above])
        if self.phase == "above" and np.linalg.norm(goal - ee) < 0.005:
            self.phase = "down"
        if self.phase == "down":
            goal = np.add(self.cube0, [0.0, 0.0, -0.03])
        q = decode_joints(obs["joint_angles"].astype(float), self.coding)
        qdot = self._qdot(q, ee, goal, obs["ee_pose"][3:])
        arm = qdot / self.task.joint_speeds(self.arm.v_max)
        return np.clip(np.append(arm, -1.0), -1.0, 1.0).astype(np.float32)


def run_scripted_lift(
    env,
    seed: int = 0,
    quat=(1.0, 0.0, 0.0, 0.0),
    align: bool = False,
    above: float = 0.06,
    **options,
) -> dict:
    """One scripted episode (the cube at yaw 0; ``align``, ``above``: :class:`ScriptedLift`'s;
    ``options``: reset options such as ``object_mass``); returns success, steps, the last
    info, and the episode's peak wrist reading (N)."""
    obs, _ = env.reset(seed=seed, options={"object_quat": np.asarray(quat), **options})
    script = ScriptedLift(env, align, above)
    step, peak = 0, 0.0
    for step in range(env.task.episode_steps):  # noqa: B007  (the count is returned)
        obs, _, done, _, info = env.step(script(obs))
        peak = max(peak, float(info["contact_force_norm"]))
        if done:
            break
    return {"success": info["is_success"], "steps": step + 1, "info": info, "peak_force": peak}
