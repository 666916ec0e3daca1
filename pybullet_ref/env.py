"""The contract on PyBullet: the arm URDF loaded directly, stepped by ``stepSimulation``.

The twin of :class:`mjx_arm.envs.mujoco_env.MujocoArmEnv`: the engine-neutral parts (spaces,
sampling, observation, reward, success) come from :class:`mjx_arm.envs.base.BaseRobotEnv`; this
file implements the physics hooks only. Each env owns one ``BulletClient`` in DIRECT mode, so
several envs (also in the subprocesses of a Gymnasium ``AsyncVectorEnv``) never share a physics
server or module state.

Joint drive: the MuJoCo model's servo, applied as joint torques. The MuJoCo model drives each
joint with ``clip(kv * (u - qdot), +-effort)`` (a velocity actuator) and adds joint damping
``-d * qdot``, reflected rotor inertia (armature) and gravity compensation. PyBullet's
``VELOCITY_CONTROL`` motor is a hard velocity constraint instead: blocked by the box it pushes
with its whole torque cap (measured: about 380 N at the tool where MuJoCo gives 26 N), so contact
forces would not be comparable. Here, at every substep, ``TORQUE_CONTROL`` applies the torque
that makes PyBullet's step MuJoCo's (:mod:`pybullet_ref.drive`): the servo and the damping
implicit, the armature on the diagonal of the mass matrix (``calculateMassMatrix``), plus
``g(q)`` from ``calculateInverseDynamics`` (MuJoCo's ``gravcomp``; gravity is -9.81 in both
engines), with the contacts' share observed from the last substep and joint-limit reactions
kept out of it. URDF joint damping is zeroed in PyBullet (Bullet applies it explicitly, which
diverges on the light wrist links; it is part of the drive). ``kv``, ``d``, the effort and the
armature are read from the converted MuJoCo model. Friction is MuJoCo's 1.0 per contact.

Self-collision as the task model has it (:func:`mjx_arm.arm.model_io.task_convert_config`):
off, so the arm is loaded without ``URDF_USE_SELF_COLLISION`` (with it, a joint-limited UR10
ran its wrist into its forearm, which MuJoCo never does); on, without MuJoCo's filtered pairs.

Contacts as MuJoCo makes them: the arm is loaded from a copy of its URDF whose collision meshes
are convex hulls shrunk by the 1 mm margin Bullet pads them with (:mod:`pybullet_ref.hulls`),
and the table, the box and the cube are compliant, calibrated on trained policies against
MuJoCo's soft contacts (:mod:`pybullet_ref.contact`, scaled per arm by
:mod:`pybullet_ref.tool_contact`; ``contact="rigid"`` keeps Bullet's).

Wrist F/T: PyBullet's sensor on the fixed F/T joint, tared, or where the F/T point is an arm
joint (or the tool holds a gripper) the sum of the tool's contact forces
(:mod:`pybullet_ref.wrench`).

Each control step starts from the joint states its previous read took (nothing moves between
the two): a change made to the world through ``env.client`` between steps shows from the
step's second substep on, and in its read.

Reset: PyBullet reproduces a seeded episode exactly only after a full rebuild, so every reset
rebuilds the world (about 5 ms without rendering, 8 ms with visual shapes), takes one substep at
rest so the F/T sensor has a reading, and puts the joints back at the sampled angles.
"""

from __future__ import annotations

import contextlib
import operator
import weakref
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pybullet_ref.fast.calls import HotCalls
from pybullet_ref.quiet import STDERR, STDOUT, native_output_silenced

with native_output_silenced((STDOUT, STDERR)):  # "pybullet build time: ..."
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

from mjx_arm.arm.config import ArmConfig
from mjx_arm.arm.model_io import task_convert_config
from mjx_arm.envs.base import DEFAULT_HEIGHT, DEFAULT_WIDTH, BaseRobotEnv, PhysicsReading
from mjx_arm.envs.camera import task_camera
from mjx_arm.paths import asset
from mjx_arm.task import sampling
from mjx_arm.task.config import TaskConfig
from mjx_arm.task.grip import ObjectStart
from mjx_arm.task.lift import cube_half
from mjx_arm.urdf.scene_shapes import CUBE_HALF, CUBE_MASS
from pybullet_ref.arm_model import (
    BASE,
    ArmIds,
    excluded_pairs,
    joint_servo,
    subtree_links,
)
from pybullet_ref.contact import SOFT, SceneContact
from pybullet_ref.drive import ArmDrive, JointLimits
from pybullet_ref.gripper import gripper_ids, pad_forces
from pybullet_ref.mimic import add_mimic_constraints
from pybullet_ref.pads import bullet_arm_urdf
from pybullet_ref.tool_contact import arm_contact
from pybullet_ref.wrench import GRAVITY, ToolTare, contact_wrench, tared_wrench

_NO_GRIP = np.zeros(0)  # the reading's grip without a gripper
# MuJoCo's sliding friction (every geom 1.0, a contact takes the larger); Bullet multiplies the
# two bodies' coefficients, so 1.0 on every body gives the same 1.0 per contact.
FRICTION = 1.0
ARM_FLAGS = pybullet.URDF_USE_INERTIA_FROM_FILE
TARGET_MARKER_RADIUS = 0.02
TARGET_MARKER_RGBA = (0.1, 0.8, 0.2, 0.5)
NEAR, FAR = 0.01, 10.0
CUBE_RGBA = (0.2, 0.35, 0.85, 1.0)


def disconnect(client: BulletClient) -> None:
    """Disconnect ``client``'s physics server once, and mark it so that its own ``__del__``
    does not try again (that retry catches ``pybullet.error``, which is gone at exit)."""
    if client._client >= 0:
        with contextlib.suppress(pybullet.error):
            client.disconnect()
        client._client = -1


class PybulletArmEnv(BaseRobotEnv):
    """The arm task on PyBullet (one world, CPU), same contract as ``MujocoArmEnv``.

    The world is rebuilt at every reset (PyBullet reproduces a seeded episode exactly only after
    a full rebuild). Self-collision and the joint drive follow the MuJoCo task model (see the
    module docstring).

    Args:
        task: the task configuration (default: Touch), or an ArmTask (a task on its arm).
        arm: the arm (a URDF, an arm file or an ArmConfig; default: the shipped arm).
        render_mode: None, "rgb_array" or "human".
        width, height: frame size (pixels).
        contact: how the table, the box and the cube push back: "soft" (compliant, calibrated
            on MuJoCo's contacts and scaled by the arm's tool mass,
            :mod:`pybullet_ref.tool_contact`; default), "rigid" (Bullet's hard contacts), a
            :class:`~pybullet_ref.contact.SceneContact` or its text form.
    """

    engine = "pybullet"

    def __init__(
        self,
        task: TaskConfig | None = None,
        arm: str | Path | ArmConfig | None = None,
        render_mode: str | None = None,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
        contact: SceneContact | str = SOFT,
    ) -> None:
        super().__init__(task, arm, render_mode, width, height)
        self.contact = arm_contact(contact, self.arm, self.task.object_scale)
        self._urdf = bullet_arm_urdf(self.arm)  # hulls eroded, repairs, pads fitted
        self._ee_offset = self.arm.ee_offset.copy() if np.any(self.arm.ee_offset) else None
        self.servo = joint_servo(self.arm, self.task.spec.servo_dt or self.task.sim_dt)
        self.self_collision = task_convert_config(self.task, self.arm).self_collision
        self.client = self._connect()
        self._calls = HotCalls.of(self.client)
        # without a render mode nothing is drawn: skip the visual shapes (halves the reset time)
        self._load_flags = 0 if render_mode else pybullet.URDF_IGNORE_VISUAL_SHAPES
        self.ids = self._lookup_ids()
        self._zeros = [0.0] * len(self.ids.joints)
        self._dof_zeros = [0.0] * len(self.ids.dofs)
        arm_in_dofs = self.ids.arm_in_dofs
        identity = arm_in_dofs == tuple(range(len(self.ids.dofs)))
        self._pick = None if identity else operator.itemgetter(*arm_in_dofs)
        self._read_states: tuple | None = None  # the joint states of the last read
        self._drive = ArmDrive.of(
            self.servo, self.ids.limits, None if identity else arm_in_dofs, self.task.sim_dt
        )
        self._u = list(self._zeros)
        self._target_body = sampling.target_body_pos(np, np.full(3, 0.5), self.task)
        self._tool_before = (np.zeros(3), np.zeros(3))
        self._tare = ToolTare(
            com=tuple(self.ids.tool_com.tolist()),
            com_offset=tuple((self.arm.tool.com - self.ids.tool_com).tolist()),
            dt=self.task.sim_dt,
            wrench_matrix=self.arm.tool.wrench_matrix,
        )
        self._target_of: tuple[np.ndarray, np.ndarray] | None = None  # body -> target point
        self._camera: tuple | None = None  # the view and projection, made at the first frame
        self._object = ObjectStart(np.array([1.0, 0.0, 0.0, 0.0]), CUBE_MASS, FRICTION)
        self.gripper = self.arm.gripper if self.task.spec.gripper else None
        # a complete world before the first reset (render, get_ee_pose): home pose, mid target
        self._physics_reset(np.asarray(self.task.home_qpos), self._target_body)

    def _connect(self) -> BulletClient:
        """This env's own physics server (DIRECT), disconnected when the env goes or at exit,
        while Python can still do it: an env left open until the interpreter tore pybullet
        down printed a TypeError from the client's ``__del__``."""
        with native_output_silenced():  # "argv[0]="
            client = BulletClient(connection_mode=pybullet.DIRECT)
        self._disconnect = weakref.finalize(self, disconnect, client)
        return client

    # ------------------------------------------------------------------ world

    def _load_arm(self) -> int:
        flags = ARM_FLAGS | self._load_flags
        if self.self_collision:  # as the task model: else Bullet's links never meet
            flags |= pybullet.URDF_USE_SELF_COLLISION
        return self.client.loadURDF(str(self._urdf), useFixedBase=True, flags=flags)

    def _lookup_ids(self) -> ArmIds:
        """Load the arm alone at q = 0 and look its indices up by name."""
        c = self.client
        c.resetSimulation()
        arm = self._load_arm()
        infos = [c.getJointInfo(arm, j) for j in range(c.getNumJoints(arm))]
        joint = {info[1].decode(): info[0] for info in infos}
        link = {info[12].decode(): info[0] for info in infos}
        joints = tuple(joint[name] for name in self.arm.joint_names)
        ft = link[self.arm.ft_link]  # the joint above the tool link (link index = joint index)
        dofs = tuple(info[0] for info in infos if info[2] != pybullet.JOINT_FIXED)
        # the tool's contacts make the reading where the F/T point is an arm joint, and with a
        # gripper: Bullet's reaction at the F/T joint carries the finger motor's and the mimic
        # constraint's forces (about 20 N while holding a 0.1 kg cube; MuJoCo reads its weight)
        contacts = ft in joints or self.task.spec.gripper
        tool_links = subtree_links(infos, ft) if contacts else frozenset()
        return ArmIds(
            joints=joints,
            ft=ft,
            ee=link[self.arm.ee_link],
            read=(*joints, ft),
            dofs=dofs,
            tool_links=tool_links,
            arm_in_dofs=tuple(dofs.index(j) for j in joints),
            tool_com=np.array(c.getDynamicsInfo(arm, ft)[3]),
            limits=JointLimits.of([infos[j][8] for j in joints], [infos[j][9] for j in joints]),
            self_collision_off=excluded_pairs(c, arm) if self.self_collision else (),
            **gripper_ids(self.arm.gripper, self.task.spec.gripper, joint, link, infos),
        )

    def _build_world(self, qpos: np.ndarray, target_body_pos: np.ndarray) -> None:
        """Rebuild the whole world: arm at ``qpos`` (rad, at rest), table, target."""
        c = self.client
        c.resetSimulation()
        c.setGravity(*GRAVITY)
        c.setTimeStep(self.task.sim_dt)
        self.body = self._load_arm()
        self._setup_arm(qpos)
        add_mimic_constraints(c, self.body, self.arm.urdf)  # after the joint states are set
        fixed = SceneContact.dynamics_of(self.contact.fixed)
        table = c.loadURDF(str(asset("table.urdf")), useFixedBase=True, flags=self._load_flags)
        c.changeDynamics(table, BASE, lateralFriction=FRICTION, **fixed)
        position = [float(v) for v in target_body_pos]
        if self.task.spec.scene.box:  # the box stands on the table
            box = c.loadURDF(
                str(asset("target_box.urdf")),
                basePosition=position,
                useFixedBase=True,
                flags=self._load_flags,
            )
            c.changeDynamics(box, BASE, lateralFriction=FRICTION, **fixed)
        elif self.render_mode and self.task.spec.scene.marker:
            self._add_target_marker(position)
        if self.gripper is not None:
            self.cube = self._add_cube(position, self._object, cube_half(self.task))

    def _add_cube(self, position: list[float], obj: ObjectStart, half: float = CUBE_HALF) -> int:
        """The free cube of a gripper task: the MuJoCo scene's size (or ``half`` edge, m), the
        episode's mass and friction (Bullet multiplies the two bodies' coefficients: the pads
        keep 1.0)."""
        c, half = self.client, [half] * 3
        shape = c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        look = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=CUBE_RGBA)
        w, x, y, z = (float(v) for v in obj.quat)
        cube = c.createMultiBody(float(obj.mass), shape, look, position, [x, y, z, w])
        c.changeDynamics(
            cube,
            BASE,
            lateralFriction=float(obj.friction),
            **SceneContact.dynamics_of(self.contact.cube),
        )
        return cube

    def _setup_arm(self, qpos: np.ndarray) -> None:
        """Dynamics, collision filter, motors, joint state and F/T sensor of a fresh arm."""
        c, arm, ids = self.client, self.body, self.ids
        for link in range(BASE, c.getNumJoints(arm)):
            c.changeDynamics(
                arm, link, linearDamping=0.0, angularDamping=0.0, lateralFriction=FRICTION
            )
        for j in ids.joints:
            c.changeDynamics(arm, j, jointDamping=0.0)
        for i, j in ids.self_collision_off:
            c.setCollisionFilterPair(arm, arm, i, j, 0)
        # free the joints of the default velocity motors: the servo acts through torques
        c.setJointMotorControlArray(arm, ids.joints, pybullet.VELOCITY_CONTROL, forces=self._zeros)
        for j, q in zip(ids.joints, qpos, strict=True):
            c.resetJointState(arm, j, float(q), 0.0)
        for j, q in ids.gripper_start:  # a gripper task's open, a linkage closed in the others
            c.resetJointState(arm, j, q, 0.0)
        c.enableJointForceTorqueSensor(arm, ids.ft, True)

    def _add_target_marker(self, position: list[float]) -> None:
        """A visual-only sphere at the reach target (no collision shape, no mass)."""
        c = self.client
        shape = c.createVisualShape(
            pybullet.GEOM_SPHERE, radius=TARGET_MARKER_RADIUS, rgbaColor=TARGET_MARKER_RGBA
        )
        c.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape, basePosition=position)

    # ------------------------------------------------------------------ engine hooks

    def _physics_reset(
        self, qpos: np.ndarray, target_body_pos: np.ndarray, obj: ObjectStart | None = None
    ) -> None:
        self._read_states = None  # the world is rebuilt: read it afresh
        self._drive.reset()
        self._target_body = np.asarray(target_body_pos, dtype=np.float64).copy()
        if obj is not None:
            self._object = obj
        self._build_world(qpos, self._target_body)
        self._physics_set_velocity_targets(np.zeros(len(self.ids.joints)))
        if self.gripper is not None:
            self._physics_set_gripper(0.0)
        # The F/T sensor reports the joint force of the last step: take one substep at rest
        # (the arm held by gravity compensation), then put the joints back at qpos, at rest.
        self._physics_step(1)
        for j, q in zip(self.ids.joints, qpos, strict=True):
            self.client.resetJointState(self.body, j, float(q), 0.0)
        self._drive.reset()
        self._tool_before = (np.zeros(3), np.zeros(3))

    def _physics_set_velocity_targets(self, qdot_target: np.ndarray) -> None:
        self._u = [float(v) for v in qdot_target]

    def _physics_set_gripper(self, speed: float) -> None:
        # a velocity motor at the MuJoCo servo's free speed against the fingers' damping, capped
        # at the servo's blocked press (an explicit torque law is too stiff for a 60 g finger)
        target, force = self.servo.finger_speed(speed), self.servo.finger_force(speed)
        mode = pybullet.VELOCITY_CONTROL
        self.client.setJointMotorControl2(
            self.body, self.ids.finger, mode, targetVelocity=target, force=force
        )

    def _physics_step(self, n_substeps: int) -> None:
        calls, body, joints = self._calls, self.body, self.ids.joints
        dofs, u = self.ids.dofs, self._u
        # the joint states of the last read, where nothing has moved since (arm-only dofs)
        states, self._read_states = self._read_states, None
        for i in range(n_substeps):
            if states is None:
                states = calls.get_joint_states(body, dofs)
            forces = self._drive.torques(calls, body, states, lambda q: u)
            calls.set_motors(body, joints, pybullet.TORQUE_CONTROL, forces=forces)
            if i == n_substeps - 1:
                self._tool_before = self._tool_velocity()
            calls.step()
            states = None

    def _physics_read(self) -> PhysicsReading:
        calls = self._calls
        states = calls.get_joint_states(self.body, self.ids.read)
        if self._pick is None:  # the next substep starts from these (dofs = joints)
            self._read_states = states[:-1]
        tool, ee = calls.get_link_states(
            self.body, [self.ids.ft, self.ids.ee], computeLinkVelocity=1, computeForwardKinematics=1
        )
        x, y, z, w = ee[5]
        ee_pos = np.array(ee[4])
        if self._ee_offset is not None:  # the ee point off the ee link's origin
            rot = np.array(pybullet.getMatrixFromQuaternion(ee[5])).reshape(3, 3)
            ee_pos += rot @ self._ee_offset
        # the arm's contacts, read once: the tool's make the wrench where the F/T point is an
        # arm joint or the tool holds a gripper, the pads' make a gripper task's pad forces
        contacts = self.client.getContactPoints(bodyA=self.body) if self.ids.tool_links else ()
        if self.ids.tool_links:
            wrench = contact_wrench(self.body, self.ids.tool_links, ee_pos, ee[5], contacts)
        else:
            wrench = tared_wrench(self._tare, states[-1][2], self._tool_before, tool)
        target, grip = self._target_point(), _NO_GRIP
        if self.gripper is not None:  # the target is the cube, wherever it is now
            grip = self._grip(contacts)
            target = grip[1:4]
        return PhysicsReading(
            ee_pos=ee_pos,
            ee_quat=np.array([w, x, y, z]),
            qpos=np.array([s[0] for s in states[:-1]]),
            qvel=np.array([s[1] for s in states[:-1]]),
            target_pos=np.asarray(target),
            wrench=wrench,
            grip=grip,
        )

    def _grip(self, contacts: Sequence[tuple]) -> np.ndarray:
        """The ``grip`` vector (:data:`mjx_arm.task.grip.GRIP_LAYOUT`): the finger's closure,
        the cube's pose and the normal force on each pad: the sum over its ``contacts`` (the
        arm's ``getContactPoints`` rows), as MuJoCo's touch sensor sums them."""
        c = self.client
        closure = self.gripper.closure(c.getJointState(self.body, self.ids.finger)[0])
        pos, (x, y, z, w) = c.getBasePositionAndOrientation(self.cube)
        pads = pad_forces(c, self.body, contacts, self.ids.pads, self.ids.pad_regions)
        return np.array([closure, *pos, w, x, y, z, *pads])

    def _render_frame(self) -> np.ndarray:
        self._camera = self._camera or self._camera_matrices()
        view, projection = self._camera
        _, _, rgba, _, _ = self.client.getCameraImage(
            self.width,
            self.height,
            viewMatrix=view,
            projectionMatrix=projection,
            renderer=pybullet.ER_TINY_RENDERER,
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(self.height, self.width, 4)[..., :3].copy()

    def close(self) -> None:
        """Disconnect this env's physics server."""
        if getattr(self, "client", None) is not None:
            self._disconnect()
            self.client = None
        super().close()

    # ------------------------------------------------------------------ helpers

    def _tool_velocity(self) -> tuple[Sequence[float], Sequence[float]]:
        """World velocity of the tool link's centre of mass and its angular velocity, 3 floats
        each."""
        state = self._calls.get_link_state(
            self.body, self.ids.ft, computeLinkVelocity=1, computeForwardKinematics=1
        )
        return state[6], state[7]

    def _target_point(self) -> np.ndarray:
        """The target point (m), ``(3,)``: where the task puts it on the target body, computed
        once per episode (the body is set, not moved, by each reset)."""
        if self._target_of is None or self._target_of[0] is not self._target_body:
            point = np.asarray(sampling.target_point(np, self._target_body, self.task))
            self._target_of = (self._target_body, point)
        return self._target_of[1]

    def _camera_matrices(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The view and projection of the camera MuJoCo renders from too: it frames the arm
        and the task area (:func:`~mjx_arm.envs.camera.task_camera`)."""
        camera = task_camera(self.arm_task, self.width / self.height)
        view = self.client.computeViewMatrix(camera.eye, camera.target, [0.0, 0.0, 1.0])
        projection = self.client.computeProjectionMatrixFOV(
            camera.fovy, self.width / self.height, NEAR, FAR
        )
        return view, projection
