"""Conversion settings and the names every converted model carries (sites, sensors,
collision bits).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field

from mjx_arm.urdf.pad_fit import FittedPads
from mjx_arm.urdf.scene_shapes import NO_SCENE, SCENES, SceneSpec

# Collision bit masks. Scene geoms (table, target box) never collide with each other. Arm geoms
# collide with the scene, and with each other only when self_collision is on.
ARM_CONTYPE, ARM_CONAFFINITY = 1, 3
ARM_CONAFFINITY_NO_SELF = 2

# Names the converted model always carries (the task code looks them up by name).
EE_SITE = "ee"
FT_SITE = "ft"
TOOL_COM_SITE = "tool_com"
SENSORS = (
    "ft_force",
    "ft_torque",
    "tool_acc",
    "tool_gyro",
    "tool_angacc",
    "ft_quat",
    "ee_pos",
    "ee_quat",
)


@dataclass(frozen=True)
class ConvertConfig:
    """How a URDF becomes an MJCF model. Saved with every run that uses it.

    Attributes:
        default_damping: joint damping (N m s/rad) for joints whose URDF gives none or zero.
        armature_per_effort: reflected rotor inertia added to each actuated joint, per unit of
            its URDF effort (kg m^2 per N m). Geared industrial joints carry a rotor inertia
            times the gear ratio squared, which grows with the joint's size: 0.005 gives
            0.75 kg m^2 on a 150 N m joint and 0.14 kg m^2 on a 28 N m wrist.
        kv_factor: velocity gain of each actuator as a multiple of ``I_min / sim_dt``, where
            ``I_min`` is the smallest apparent inertia ``1 / (M^-1)_jj`` of that joint over the
            joint ranges (what the joint feels when the others move freely).
            At 1.0 a substep halves the velocity error, and a torque-capped actuator cannot
            chatter: MuJoCo drops the implicit derivative of a clamped actuator, and an
            explicit step stays inside the error band while ``kv * dt / I <= 1``.
        gravity_compensation: compensate the arm's weight through its actuators (inside the
            effort limit), as an industrial arm's joint controllers do.
        ee_link: link whose frame is the end-effector point; None picks ``ee_link`` if present,
            else the deepest link of the tree.
        ee_offset: where the end-effector point (the ``ee`` site) sits in ``ee_link``'s frame
            (m); the site keeps the link's orientation.
        ft_joint: fixed joint where the wrist force/torque reading is taken; None picks
            ``ft_sensor_joint`` if present, else the joint above the end-effector body.
        sim_dt: physics time step (s).
        servo_dt: the step (s) the velocity gains are computed for (``kv_factor``); 0 takes
            ``sim_dt``. A task that steps finer than its servos were tuned for (Lift at 480 Hz
            keeps the 240 Hz gains) sets it, so a finer step changes the integration only.
        pad_links: links that get a touch sensor ``LINK_touch`` over their collision box (the
            finger pads of a gripper): the sum of the normal contact forces on the link (N).
        pads: a gripper's pads fitted to their meshes (:mod:`mjx_arm.urdf.pad_fit`): their
            links' collision meshes are replaced by the fitted boxes and the kept parts of cut
            meshes (:func:`mjx_arm.urdf.collision_fit.fit_pads`); None keeps the URDF's.
        effort_caps: ``(joint, effort)`` pairs: those joints' actuators push at most that
            (N m or N) where the URDF allows more (a jaw's squeeze,
            :attr:`mjx_arm.arm.gripper.Gripper.effort_cap`).
        rest_qpos: joints the model starts at other than 0 (``qpos0``), ``(name, position)``
            pairs: a linkage gripper held closed (:func:`mjx_arm.urdf.convert.load_model`).
        solver_iterations: constraint solver iterations (few, for MJX speed). On an H200 the
            Touch scene steps 1.6M physics steps/s at 4 iterations (line search 8), 3.2M at
            2 (4) and 5.0M at 1 (2), 32k envs (``benchmarks/results/sweep/*.json``).
        ls_iterations: line-search iterations of the Newton solver.
        scene: the task scene added around the arm (:class:`~mjx_arm.urdf.scene_shapes.SceneSpec`;
            a name of :data:`~mjx_arm.urdf.scene_shapes.SCENES` is read as that scene).
        package_dirs: ``package://NAME`` -> directory; unnamed packages are searched for upwards
            from the URDF's folder.
        repair_inertia: replace inertia tensors that break the triangle inequality (or are not
            positive definite) by the nearest valid one instead of failing.
        default_effort, default_velocity: the effort (N m or N) and velocity (rad/s or m/s)
            limit of every moving joint whose URDF gives none (or 0); 0 leaves such a joint an
            error. The validator reports each use as a warning.
        self_collision: let non-neighbouring arm links collide with each other. The task
            models turn it off: the tasks keep the arm near its home pose, and dropping the
            self pairs cuts MJX's contact rows from 374 to about a quarter.
        collision: "mesh" keeps the arm's collision meshes; "capsule" or "box" replaces each
            by that primitive, fitted to the mesh by MuJoCo's compiler (faster contacts in
            MJX; PyBullet, which reads the URDF, keeps the meshes).
        convert_meshes: convert collision meshes MuJoCo cannot read (Collada ``.dae``, PLY,
            glTF, ...) to binary STL with trimesh; off, such a mesh is an error.
        mesh_cache_dir: folder of the converted meshes (named by a hash of the source file,
            reused on the next conversion); None uses ``~/.cache/mjx_arm/meshes``.
    """

    default_damping: float = 1.0
    armature_per_effort: float = 0.005
    kv_factor: float = 1.0
    gravity_compensation: bool = True
    ee_link: str | None = None
    ee_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ft_joint: str | None = None
    sim_dt: float = 1.0 / 240.0
    servo_dt: float = 0.0
    pad_links: tuple[str, ...] = ()
    pads: FittedPads | None = None
    effort_caps: tuple[tuple[str, float], ...] = ()
    rest_qpos: tuple[tuple[str, float], ...] = ()
    solver_iterations: int = 2
    ls_iterations: int = 4
    scene: SceneSpec = NO_SCENE
    package_dirs: Mapping[str, str] = field(default_factory=dict)
    repair_inertia: bool = False
    default_effort: float = 0.0
    default_velocity: float = 0.0
    self_collision: bool = True
    collision: str = "mesh"
    convert_meshes: bool = True
    mesh_cache_dir: str | None = None

    def __post_init__(self) -> None:
        if isinstance(self.scene, str) and self.scene in SCENES:
            object.__setattr__(self, "scene", SCENES[self.scene])

    def default_limits(self) -> dict[str, float]:
        """``effort``/``velocity`` -> the value the converter supplies where a joint has none."""
        return {"effort": self.default_effort, "velocity": self.default_velocity}

    def replace(self, **changes) -> ConvertConfig:
        """Return a copy with some fields changed."""
        return dataclasses.replace(self, **changes)
