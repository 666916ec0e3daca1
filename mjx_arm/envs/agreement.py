"""Do MJX (JAX or Warp) and C MuJoCo step the task model alike? Same states, same actions.

Three checks, each on batches of start states and action sequences played open loop in every
physics: forward kinematics at random joint angles, joint state after open-loop actions (free
motion, the Reach scene), and the tared F/T reading while the tool presses the box (the Touch
scene; the press commands are recorded once from a Jacobian controller in C MuJoCo and replayed
in the others). C MuJoCo runs in float64, MJX in float32.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from mjx_arm.envs.arm import ArmInfo, arm_info
from mjx_arm.envs.mjx_physics import MjxPhysics
from mjx_arm.envs.model_io import SensorReader, arm_model
from mjx_arm.envs.physics_config import PhysicsConfig
from mjx_arm.task import sampling
from mjx_arm.task.config import HOME_QPOS, TaskConfig, reach_config, touch_config
from mjx_arm.urdf.convert import EE_SITE
from mjx_arm.urdf.scene import TARGET_BODY


@dataclass
class Trace:
    """Per-step read-outs of a batch of rollouts.

    Attributes:
        qpos, qvel: joint angles (rad) and velocities (rad/s), ``(B, T, 6)``.
        ee_pos: ee point (m), ``(B, T, 3)``.
        wrench: tared F/T reading (N, N m), ``(B, T, 6)``.
    """

    qpos: np.ndarray
    qvel: np.ndarray
    ee_pos: np.ndarray
    wrench: np.ndarray


class CPhysics:
    """The task model stepped by C MuJoCo (float64), read like the envs read it."""

    def __init__(self, task: TaskConfig, arm: ArmInfo | None = None) -> None:
        self.task, self.arm = task, arm or arm_info()
        self.model = arm_model(self.arm.urdf, task)
        self.data = mujoco.MjData(self.model)
        self.ids = SensorReader(self.model, self.arm)
        self.mocap = int(self.model.body_mocapid[self.model.body(TARGET_BODY).id])
        self.scale = task.action_scale * self.arm.v_max

    def start(self, qpos: np.ndarray, target_body: np.ndarray) -> None:
        """Put the arm at rest at ``qpos (6,)`` and the target body at ``(3,)``."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self.ids.qpos_adr] = qpos
        self.data.mocap_pos[self.mocap] = target_body
        mujoco.mj_forward(self.model, self.data)

    def step(self, action: np.ndarray) -> None:
        """One control step of ``action (6,)`` in [-1, 1]."""
        self.data.ctrl[self.ids.actuators] = np.clip(action, -1, 1) * self.scale
        mujoco.mj_step(self.model, self.data, nstep=self.task.n_substeps)

    def read(self) -> tuple[np.ndarray, ...]:
        """(qpos, qvel, ee_pos, wrench) now."""
        d, ids = self.data, self.ids
        return (
            d.qpos[ids.qpos_adr].copy(),
            d.qvel[ids.dof_adr].copy(),
            d.site_xpos[ids.ee_site].copy(),
            ids.wrench(np, d.sensordata.copy()),
        )

    def rollout(self, qpos0: np.ndarray, targets: np.ndarray, actions: np.ndarray) -> Trace:
        """Play ``actions (B, T, 6)`` from ``qpos0 (B, 6)`` with target bodies ``(B, 3)``."""
        rows = []
        for q, target, seq in zip(qpos0, targets, actions, strict=True):
            self.start(q, target)
            steps = []
            for action in seq:
                self.step(action)
                steps.append(self.read())
            rows.append([np.stack(x) for x in zip(*steps, strict=True)])
        return Trace(*(np.stack(x) for x in zip(*rows, strict=True)))

    def jacobian(self, qpos: np.ndarray) -> np.ndarray:
        """``(3, 6)`` position Jacobian of the ee site at ``qpos`` (scratch data)."""
        data = mujoco.MjData(self.model)
        data.qpos[self.ids.qpos_adr] = qpos
        mujoco.mj_kinematics(self.model, data)
        mujoco.mj_comPos(self.model, data)
        jacp = np.zeros((3, self.model.nv))
        mujoco.mj_jacSite(self.model, data, jacp, None, self.model.site(EE_SITE).id)
        return jacp[:, self.ids.dof_adr]


def mjx_rollout(
    physics: MjxPhysics, qpos0: np.ndarray, targets: np.ndarray, actions: np.ndarray
) -> Trace:
    """:meth:`CPhysics.rollout` on MJX: one jitted, vmapped scan over the batch."""
    scale = jnp.asarray(physics.task.action_scale * physics.ids.arm.v_max, jnp.float32)

    def one(q, target, seq):
        def body(data, action):
            data = physics.step(data, jnp.clip(action, -1, 1) * scale)
            r = physics.read(data)
            return data, (r.qpos, r.qvel, r.ee_pos, r.wrench)

        _, out = jax.lax.scan(body, physics.init(q, target), seq)
        return out

    run = jax.jit(jax.vmap(one))
    out = run(*(jnp.asarray(x, jnp.float32) for x in (qpos0, targets, actions)))
    return Trace(*(np.asarray(x, np.float64) for x in out))


def mjx_fk(physics: MjxPhysics, qpos: np.ndarray) -> np.ndarray:
    """ee point (m) at joint angles ``qpos (B, 6)`` by MJX's forward pass, ``(B, 3)``."""
    target = jnp.asarray([0.5, 0.0, 0.2], jnp.float32)
    init = jax.jit(jax.vmap(lambda q: physics.read(physics.init(q, target)).ee_pos))
    return np.asarray(init(jnp.asarray(qpos, jnp.float32)), np.float64)


def c_fk(c: CPhysics, qpos: np.ndarray) -> np.ndarray:
    """ee point (m) at joint angles ``qpos (B, 6)`` by C MuJoCo, ``(B, 3)``."""
    out = []
    for q in qpos:
        c.start(q, np.array([0.5, 0.0, 0.2]))
        out.append(c.data.site_xpos[c.ids.ee_site].copy())
    return np.array(out)


def random_joint_angles(arm: ArmInfo, n: int, seed: int) -> np.ndarray:
    """``(n, 6)`` joint angles uniform inside the limits (clipped to +-pi)."""
    rng = np.random.default_rng(seed)
    low, high = np.maximum(arm.lower, -np.pi), np.minimum(arm.upper, np.pi)
    return rng.uniform(low, high, (n, 6))


def open_loop_inputs(
    task: TaskConfig, n: int, steps: int, seed: int, hold: int = 5
) -> tuple[np.ndarray, ...]:
    """Start poses ``(n, 6)``, Reach targets ``(n, 3)`` and piecewise-constant uniform actions
    ``(n, steps, 6)`` (a new level every ``hold`` steps), at half amplitude so the arm stays in
    free space."""
    rng = np.random.default_rng(seed)
    qpos0 = sampling.initial_qpos(np, rng.uniform(size=(n, 6)), task)
    targets = sampling.target_body_pos(np, rng.uniform(size=(n, 3)), task)
    levels = 0.5 * rng.uniform(-1.0, 1.0, (n, -(-steps // hold), 6))
    actions = np.repeat(levels, hold, axis=1)[:, :steps]
    return qpos0, targets, actions.astype(np.float32)


def press_inputs(
    c: CPhysics, boxes: np.ndarray, steps: int = 60, depth: float = 0.01
) -> tuple[np.ndarray, ...]:
    """Press commands recorded in C MuJoCo: drive the ee ``depth`` below each box's top centre.

    Returns:
        Start poses ``(B, 6)`` (the home pose), box bodies ``(B, 3)``, actions ``(B, steps, 6)``.
    """
    qpos0 = np.tile(np.asarray(HOME_QPOS), (len(boxes), 1))
    all_actions = []
    for q, box in zip(qpos0, boxes, strict=True):
        c.start(q, box)
        target = sampling.target_point(np, box, c.task) + np.array([0.0, 0.0, -depth])
        actions = []
        for _ in range(steps):
            qpos, _, ee, _ = c.read()
            v = np.linalg.lstsq(c.jacobian(qpos), 2.0 * (target - ee), rcond=None)[0]
            action = np.clip(v / c.scale, -1.0, 1.0)
            c.step(action)
            actions.append(action)
        all_actions.append(actions)
    return qpos0, boxes, np.asarray(all_actions, np.float32)


def agreement(impls: tuple[str, ...], n_fk: int, n_open: int, seconds: float, seed: int = 0):
    """Run the three checks for each MJX implementation in ``impls`` against C MuJoCo.

    Returns:
        Dict impl -> figures: ``fk_max_m``; ``open_loop_qpos_max_rad`` / ``_median_rad`` (after
        ``seconds``); ``press_force_c_n`` / ``press_force_mjx_n`` (mean |F| of the last 10 steps,
        per box) and ``press_force_max_rel``.
    """
    reach, touch = reach_config(), touch_config(terminate_on_success=False)
    arm = arm_info()
    c_reach, c_touch = CPhysics(reach, arm), CPhysics(touch, arm)
    qs = random_joint_angles(arm, n_fk, seed)
    fk_c = c_fk(c_reach, qs)
    steps = round(seconds / reach.ctrl_dt)
    q0, targets, actions = open_loop_inputs(reach, n_open, steps, seed)
    ref_open = c_reach.rollout(q0, targets, actions)
    boxes = np.array([[0.5, 0.05, 0.0], [0.4, -0.2, 0.0], [0.6, 0.2, 0.0], [0.45, 0.1, 0.0]])
    pq, pb, pa = press_inputs(c_touch, boxes)
    ref_press = c_touch.rollout(pq, pb, pa)
    f_c = np.linalg.norm(ref_press.wrench[:, -10:, :3], axis=-1).mean(axis=1)
    out = {}
    for impl in impls:
        config = PhysicsConfig(impl=impl)
        phys_reach = MjxPhysics(c_reach.model, arm, reach, config, batch_size=max(n_fk, n_open))
        phys_touch = MjxPhysics(c_touch.model, arm, touch, config, batch_size=len(boxes))
        fk = mjx_fk(phys_reach, qs)
        tr = mjx_rollout(phys_reach, q0, targets, actions)
        dq = np.abs(tr.qpos[:, -1] - ref_open.qpos[:, -1]).max(axis=1)
        press = mjx_rollout(phys_touch, pq, pb, pa)
        f_m = np.linalg.norm(press.wrench[:, -10:, :3], axis=-1).mean(axis=1)
        out[impl] = {
            "fk_max_m": float(np.abs(fk - fk_c).max()),
            "open_loop_seconds": seconds,
            "open_loop_qpos_max_rad": float(dq.max()),
            "open_loop_qpos_median_rad": float(np.median(dq)),
            "open_loop_free_motion_force_max_n": float(
                np.linalg.norm(tr.wrench[..., :3], axis=-1).max()
            ),
            "press_force_c_n": f_c.tolist(),
            "press_force_mjx_n": f_m.tolist(),
            "press_force_max_rel": float(np.max(np.abs(f_m - f_c) / f_c)),
        }
    return out
