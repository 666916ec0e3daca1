"""Position-controlled copies of the CPU envs: the same task, a position servo on each joint.

A real UR5e takes joint position targets (URScript ``servoj``, or a ROS 2 position controller)
where the training envs take velocity targets. These envs keep everything of the contract
(spaces, observation, reward, success, termination, sampling: all from :class:`BaseRobotEnv`)
and change only the actuation. The action is still the contract's velocity action; the env's
velocity hook passes the joint velocity targets through the sim-to-real chain,
:class:`VelocityToPositionAdapter` then :class:`SafetyLimiter`, and the limiter's command becomes
the position servos' target. A policy runs on these envs unchanged, and what the robot would
have been sent is logged per episode (:attr:`episodes`).

The servo is a position loop around the env's own velocity servo, as in an industrial joint
drive (position loop, velocity loop, current loop)::

    torque = clip(kv * (K * (q_target - q) - qdot), +-effort)

``kv`` is the velocity actuator's gain of the converted model (the smallest apparent joint
inertia over the joint ranges divided by ``sim_dt``, see
:class:`mjx_arm.urdf.convert.ConvertConfig`), ``effort`` the URDF torque cap and ``K`` the
position-loop gain (1/s) of :class:`ServoConfig`. So ``kp = K * kv`` and the damping is the
velocity loop's own ``kv``. Gravity compensation, joint damping and armature are the velocity
model's. In MuJoCo the loop is a ``position`` actuator (``kp``, ``kv``), made by editing the
compiled task model's actuators in place (the model's ids and sensors are those of the velocity
env); in PyBullet it is applied as torques at every substep, like the velocity servo there
(:mod:`mjx_arm.sim2real.position_pybullet`).

How the commands reach the servo (:class:`ServoConfig`). By default they are streamed at the
servo rate with velocity feed-forward, as a drive's trajectory interface does: within a control
period the reference runs on the line from the previous command to the current one, and the
velocity target is ``v_cmd + clip(K * (q_ref - q), +-cap)`` with ``v_cmd`` the limiter's command
velocity (in MuJoCo: the position actuator's control is ``q`` plus that target over ``K``). The
feed-forward does the moving, so ``K`` (3 /s, capped at 0.1 rad/s) only takes drift back onto
the command path and the arm stays about as compliant to contact as the velocity servo the
policy was trained on. With ``feedforward``
off, each command is held for the whole control period and the loop is ``K * (q_cmd - q)``
alone: to move at ``v`` the command must lead the arm by ``v / K`` and a period of motion, and a
joint blocked by the table or the cube pushes that much harder (Lift lost up to half its
episodes that way in C MuJoCo: benchmarks/results/sim2real/).

Stability: around one joint of inertia ``I`` the loop is ``I s^2 + kv s + kv K``. With
``b = kv / I`` (the velocity loop's bandwidth: 240 /s at the smallest inertia, about 100 /s for
the shoulder lift at the home pose) the damping ratio is ``0.5 * sqrt(b / K)``: above 1 for
every joint at ``K = 3`` or 10 (0.79 at the shoulder lift for ``K = 40``), so no joint rings.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import mujoco
import numpy as np

from mjx_arm import engines
from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.info import ArmInfo
from mjx_arm.arm.resolve import ArmTask
from mjx_arm.envs.base import DEFAULT_HEIGHT, DEFAULT_WIDTH
from mjx_arm.envs.mujoco_env import MujocoArmEnv
from mjx_arm.sim2real.adapter import VelocityToPositionAdapter
from mjx_arm.sim2real.gripper import GripperPassthrough
from mjx_arm.sim2real.limiter import JointLimits, SafetyLimiter
from mjx_arm.sim2real.settings import ChainConfig, ServoConfig
from mjx_arm.task.config import TaskConfig


@dataclass(frozen=True)
class ServoGains:
    """Per-joint gains of the position servo, contract joint order.

    Attributes:
        kp: position gain (N m/rad), ``(6,)``.
        kv: velocity gain (N m s/rad), ``(6,)``.
        effort: torque cap (N m), ``(6,)``.
    """

    kp: np.ndarray
    kv: np.ndarray
    effort: np.ndarray

    def to_dict(self, names: tuple[str, ...]) -> dict[str, dict[str, float]]:
        """``{joint: {kp, kv, effort}}``, JSON-ready."""
        return {
            name: {"kp": float(p), "kv": float(v), "effort": float(e)}
            for name, p, v, e in zip(names, self.kp, self.kv, self.effort, strict=True)
        }


def servo_gains(kv: np.ndarray, effort: np.ndarray, config: ServoConfig) -> ServoGains:
    """The position servo around velocity servos of gains ``kv (6,)`` and caps ``effort (6,)``."""
    kv = np.asarray(kv, dtype=np.float64)
    return ServoGains(kp=config.position_gain * kv, kv=kv, effort=np.asarray(effort, np.float64))


def use_position_servos(
    model: mujoco.MjModel, actuators: np.ndarray, arm: ArmInfo, config: ServoConfig
) -> ServoGains:
    """Turn the velocity actuators ``actuators (6,)`` of ``model`` into position servos.

    In place: gain ``kp``, bias ``(0, -kp, -kv)`` (MuJoCo's ``position`` actuator with ``kv``),
    control range = the URDF joint range (widened by ``(v_max + cap) / K`` for the feed-forward
    stream, whose control is the measured angle plus its velocity target over ``K``). The
    force range (the URDF effort) is kept.

    Raises:
        ValueError: an actuator is not the converter's velocity actuator.
    """
    kv = model.actuator_gainprm[actuators, 0].copy()
    bias = model.actuator_biasprm[actuators, :3]
    if not np.allclose(bias, np.stack([np.zeros_like(kv), np.zeros_like(kv), -kv], axis=1)):
        raise ValueError(f"expected velocity actuators (bias 0, 0, -kv), got biasprm {bias}")
    gains = servo_gains(kv, model.actuator_forcerange[actuators, 1], config)
    model.actuator_gainprm[actuators, 0] = gains.kp
    model.actuator_biasprm[actuators, 1] = -gains.kp
    model.actuator_biasprm[actuators, 2] = -gains.kv
    # the feed-forward servo's control is the reference plus at most v_max / K
    reach = (arm.v_max + config.correction_limit) / config.position_gain
    reach = reach if config.feedforward else 0.0
    model.actuator_ctrlrange[actuators] = np.stack([arm.lower - reach, arm.upper + reach], axis=1)
    return gains


@dataclass
class EpisodeCommands:
    """What the chain sent in one episode and what the arm did.

    Attributes:
        commands: the limiter's position commands (rad), one ``(n,)`` per step.
        velocities: their velocities (rad/s), one ``(n,)`` per step.
        measured: joint angles (rad) one control period after each command.
        gripper: a gripper task's finger position targets (m), one per step (empty otherwise).
    """

    commands: list[np.ndarray] = field(default_factory=list)
    velocities: list[np.ndarray] = field(default_factory=list)
    measured: list[np.ndarray] = field(default_factory=list)
    gripper: list[float] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        """The three lists as ``(T, n)`` arrays (``(0, 0)`` for an episode without steps)."""
        out = {}
        for key in asdict(self):
            rows = getattr(self, key)
            out[key] = np.array(rows, np.float64) if rows else np.zeros((0, 0))
        return out


class _ChainActuation:
    """Velocity targets -> adapter -> limiter -> position servo targets.

    Mixed in before the engine's env class; the engine supplies
    ``_physics_set_position_targets``. The velocity hook is ignored while ``_holding`` (an
    engine's reset may command zero velocity while it rebuilds the world).
    """

    arm: ArmInfo
    task: TaskConfig

    def _setup_chain(self, config: ChainConfig) -> None:
        self.chain_config = config
        self.limits = JointLimits.from_urdf(self.arm.config, config.limiter)
        home = np.asarray(self.task.home_qpos, dtype=np.float64)
        dt, lim = self.task.ctrl_dt, self.limits
        self.adapter = VelocityToPositionAdapter(dt, config.tau, home, lim.lower, lim.upper)
        self.limiter = SafetyLimiter(lim, dt, home)
        self.gripper_chain = None
        gripper = self.arm.gripper
        if gripper is not None and self.task.spec.gripper:
            lower = float(self.gripper_lower())
            upper = lower + gripper.stroke
            self.gripper_chain = GripperPassthrough(lower, upper, gripper.v_max, dt, config.gripper)
        self.episodes: list[EpisodeCommands] = []
        self._holding = False

    def _physics_set_gripper(self, speed: float) -> None:
        """The gripper's command through its passthrough: a position target, then the
        stand-in's position loop around the finger's velocity servo."""
        if self._holding or self.gripper_chain is None:
            return
        self.gripper_chain.step(speed)
        self._finger_velocity(self.gripper_chain.servo_speed(self.finger_position()))

    def _physics_set_velocity_targets(self, qdot_target: np.ndarray) -> None:
        if not self._holding:
            self._previous_command = self.limiter.command
            self._physics_set_position_targets(self.limiter(self.adapter.step(qdot_target)))

    def _servo_velocity(self, fraction: float, q: np.ndarray) -> np.ndarray:
        """The feed-forward stream's joint velocity target ``(6,)`` (rad/s) ``fraction`` (0 to
        1) of the way through the control period, at the measured angles ``q (6,)`` (rad):
        the command's velocity plus ``K`` times the gap to the line from the previous command
        to the current one, that correction capped at the servo's ``correction_limit``."""
        servo = self.chain_config.servo
        q0, q1 = self._previous_command, self.limiter.command
        gap = q0 + fraction * (q1 - q0) - q
        cap = servo.correction_limit
        return self.limiter.velocity + np.clip(servo.position_gain * gap, -cap, cap)

    def _start_chain(self) -> None:
        """Start adapter and limiter at the measured joint angles; the servo holds them."""
        q = self.measured_qpos()
        self.adapter.reset(q)
        self.limiter.reset(q)
        self._previous_command = q.copy()
        self._physics_set_position_targets(q)
        if self.gripper_chain is not None:
            self.gripper_chain.reset(self.finger_position())

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Reset the episode (see :meth:`BaseRobotEnv.reset`) and start a new command log."""
        result = super().reset(seed=seed, options=options)
        self.episodes.append(EpisodeCommands())
        return result

    def step(self, action):
        """One contract action through the chain (see :meth:`BaseRobotEnv.step`), logged."""
        result = super().step(action)
        if self.episodes:
            log = self.episodes[-1]
            log.commands.append(self.limiter.command)
            log.velocities.append(self.limiter.velocity)
            log.measured.append(self.measured_qpos())
            if self.gripper_chain is not None:
                log.gripper.append(self.gripper_chain.target)
        return result

    def measured_qpos(self) -> np.ndarray:
        """Joint angles (rad, not wrapped) as the joint encoders read them now, ``(6,)``."""
        return self._physics_read().qpos


class MujocoPositionArmEnv(_ChainActuation, MujocoArmEnv):
    """:class:`MujocoArmEnv` driven through the chain into position servos.

    Args:
        task: the task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`), or a task
            configuration (default: Touch) resolved with ``arm``.
        arm: with a task configuration, the arm (a URDF, an arm file or an ArmConfig;
            default: the shipped arm).
        config: the chain and the servo (default: :class:`ChainConfig()`).
        render_mode, width, height: as for :class:`MujocoArmEnv`.
    """

    def __init__(
        self,
        task: TaskConfig | ArmTask | None = None,
        arm: str | Path | ArmConfig | None = None,
        config: ChainConfig | None = None,
        render_mode: str | None = None,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
    ) -> None:
        super().__init__(task, arm, render_mode, width, height)
        config = config or ChainConfig()
        self._setup_chain(config)
        self.gains = use_position_servos(self.model, self.ids.actuators, self.arm, config.servo)

    def _physics_reset(self, qpos, target_body_pos, obj=None) -> None:
        super()._physics_reset(qpos, target_body_pos, obj)
        self._start_chain()
        # the parent's forward pass saw ctrl = 0, a pull towards q = 0 that moves the
        # accelerations (and so the F/T reading): redo it with the servo holding the start
        mujoco.mj_forward(self.model, self.data)
        mujoco.mj_rnePostConstraint(self.model, self.data)
        mujoco.mj_sensorAcc(self.model, self.data)

    def _physics_set_position_targets(self, q_target: np.ndarray) -> None:
        self._ctrl[self._act] = q_target

    def _physics_step(self, n_substeps: int) -> None:
        if not self.chain_config.servo.feedforward or self._holding:
            super()._physics_step(n_substeps)
            return
        # kp * (ctrl - q) = kv * v with ctrl = q + v / K: the velocity servo's law
        gain = self.chain_config.servo.position_gain
        for i in range(n_substeps):
            q = self._qpos[self._qpos_adr]
            self._ctrl[self._act] = q + self._servo_velocity((i + 1) / n_substeps, q) / gain
            mujoco.mj_step(self.model, self.data)

    def gripper_lower(self) -> float:
        """The driven finger's open position (m)."""
        return self.grip.lower

    def finger_position(self) -> float:
        """The driven finger's position (m)."""
        return float(self.data.qpos[self.grip.finger_qpos])

    def _finger_velocity(self, speed: float) -> None:
        MujocoArmEnv._physics_set_gripper(self, speed)


def make_position_env(
    task: TaskConfig | ArmTask, engine: str, config: ChainConfig | None = None, **kwargs
):
    """A position-controlled env of ``task`` on ``engine`` (a registered engine with a position
    env: :func:`mjx_arm.engines.engine_names` ``("position_env")``), truncated at its task's
    ``episode_steps`` (as the arm's setup fills them in) like the registered envs.

    Args:
        task: the task on its arm (:class:`~mjx_arm.arm.resolve.ArmTask`), or a task
            configuration resolved with the ``arm`` of ``kwargs``.
        engine: the CPU engine.
        config: the chain and the servo.
        kwargs: ``arm`` (None with an ArmTask), ``render_mode``, ``width``, ``height``.
    """
    choices = engines.engine_names("position_env")
    if engine not in choices:
        raise ValueError(f"engine must be one of {choices}, got {engine!r}")
    engines.check_installed(engine)
    env = engines.load(engines.engine(engine).position_env)(task, config=config, **kwargs)
    return gym.wrappers.TimeLimit(env, env.task.episode_steps)
