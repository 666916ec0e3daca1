"""An arm is a config: its URDF, end effector, actuated joints, home pose and F/T point.

Every field may be left empty; :func:`resolve_arm` fills it from the URDF:

- ``ee_link``: a link named ``ee_link`` if there is one, else the tip of the longest chain of
  arm joints (revolute or continuous); a leaf reached through a prismatic joint is a finger,
  not a tip; a hand's TCP frame, or the link a single jaw hangs from
  (:func:`~mjx_arm.arm.chain.jaw_joint`).
- ``joints``: the revolute and continuous joints from the base down to ``ee_link``. Gripper
  joints (prismatic fingers, a jaw, and anything off the chain) are left out.
- ``home_qpos``: here, the middle of each joint's limits (a full-turn joint: 0; the shipped
  arms: their tool-down pose). The home a task starts from is derived per task from the model
  (:mod:`mjx_arm.arm.setup`) unless the config names one.
- ``ft_joint``: a fixed joint named ``ft_sensor_joint`` if there is one; else the wrist
  force/torque reading is taken where the last arm joint meets its child link.

``ee_offset`` and ``kv_factor`` are derived from the arm's model (:mod:`mjx_arm.arm.info`).

An arm file is TOML or JSON with the same fields; a relative ``urdf`` path is read from the
file's folder, and ``package://NAME/...`` from the ROS package NAME (found through the
``ROS_PACKAGE_PATH`` variable or above the arm file, as mesh paths are).
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mjx_arm.arm.chain import ARM_JOINT_TYPES as ARM_JOINT_TYPES  # the chain moved there
from mjx_arm.arm.chain import JAW_MAX_RANGE as JAW_MAX_RANGE
from mjx_arm.arm.chain import MAX_JOINTS, MIN_JOINTS, ArmConfigError, arm_chain, default_ee_link
from mjx_arm.arm.chain import NAMED_EE_LINK as NAMED_EE_LINK
from mjx_arm.arm.chain import jaw_joint as jaw_joint
from mjx_arm.inputs import MissingInputError, read_text, require_file
from mjx_arm.paths import assets_dir, default_arm_urdf
from mjx_arm.settings import config_fields
from mjx_arm.urdf.convert_config import ConvertConfig
from mjx_arm.urdf.meshes import PACKAGE_PREFIX, find_package_dir
from mjx_arm.urdf.model import Joint, RobotModel, parse_urdf

NAMED_FT_JOINT = "ft_sensor_joint"
ARM_FILE_SUFFIXES = (".toml", ".json")
COLLISION_CHOICES = ("mesh", "capsule", "box")
# The arms in assets/: the UR5e-class arm, and the same arm with a parallel-jaw gripper.
SHIPPED_ARMS = ("ur5e.urdf", "ur5e_gripper.urdf")
# The scene's pieces among the URDFs in assets/ (every other one is an arm, named by its stem).
_SCENE_URDFS = ("table", "target_box")
# The shipped arms' home pose: tool pointing down, about 0.37 m above the table, in front of the
# base (UR joint conventions).
SHIPPED_HOME_QPOS = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)


@dataclass(frozen=True)
class ArmConfig:
    """Which arm the tasks drive. Saved with every run and recorded in every policy file.

    Attributes:
        urdf: path of the arm URDF; "" is the shipped UR5e-class arm.
        ee_link: the link whose origin is the end-effector point; "" picks the default.
        joints: the actuated joints, base to wrist; () picks the chain to ``ee_link``.
        home_qpos: joint angles (rad) episodes start around; () picks the default.
        ft_joint: the fixed joint of the wrist force/torque reading; "" picks the default.
        collision: the arm's collision shapes in MuJoCo and MJX: "mesh" (as the URDF gives
            them), or "capsule" / "box" fitted to each mesh
            (:class:`~mjx_arm.urdf.convert_config.ConvertConfig`).
        repair_inertia, default_effort, default_velocity: the converter's repairs
            (``--repair-inertia``, ``--default-effort``, ``--default-velocity``) for a URDF
            that needs them; the joints that use a default limit take it here too.
        kv_factor: the joints' velocity servo gain as a multiple of ``I_min / sim_dt``
            (:class:`~mjx_arm.urdf.convert_config.ConvertConfig`); 0 derives it from the
            model so the arm presses the box like the shipped arm
            (:func:`mjx_arm.arm.info.press_kv_factor`; the shipped arms: 1). Configs recorded
            before this field existed read 1, what they trained with.
        ee_offset: the end-effector point in ``ee_link``'s frame (m, 3 values); () derives it:
            where the tool, its gripper closed, meets a surface pressed against it along the
            tool axis (:func:`mjx_arm.arm.points.derive_tool_point`; the shipped arms and arms
            with a parallel gripper: the link's origin). Configs recorded before this field
            existed read (0, 0, 0).
    """

    urdf: str = ""
    ee_link: str = ""
    joints: tuple[str, ...] = ()
    home_qpos: tuple[float, ...] = ()
    ft_joint: str = ""
    collision: str = "mesh"
    repair_inertia: bool = False
    default_effort: float = 0.0
    default_velocity: float = 0.0
    kv_factor: float = 0.0
    ee_offset: tuple[float, ...] = ()

    def convert_config(self, ee_link: str, ft_joint: str, **fields: Any) -> ConvertConfig:
        """Conversion settings of this arm, given its resolved ``ee_link`` and ``ft_joint``
        ("" for the last arm joint): its collision shapes and repairs, and ``fields``."""
        return ConvertConfig(
            ee_link=ee_link,
            ft_joint=ft_joint or None,
            collision=self.collision,
            repair_inertia=self.repair_inertia,
            default_effort=self.default_effort,
            default_velocity=self.default_velocity,
            **fields,
        )

    def default_limits(self) -> dict[str, float]:
        """``effort``/``velocity`` -> the value supplied where a joint has none."""
        return {"effort": self.default_effort, "velocity": self.default_velocity}

    def __post_init__(self) -> None:
        if self.collision not in COLLISION_CHOICES:
            raise ArmConfigError(f"collision must be one of {COLLISION_CHOICES}")
        if not 0.0 <= self.kv_factor <= 1.0:
            raise ArmConfigError(f"kv_factor must be in [0, 1] (0: derived), got {self.kv_factor}")
        if len(self.ee_offset) not in (0, 3) or not all(map(math.isfinite, self.ee_offset)):
            raise ArmConfigError(
                f"ee_offset must be 3 finite numbers (m) or empty (derived), got {self.ee_offset}"
            )

    @property
    def urdf_path(self) -> Path:
        """The URDF's absolute path (the shipped arm's when ``urdf`` is empty)."""
        return Path(self.urdf).expanduser().resolve() if self.urdf else default_arm_urdf()

    def replace(self, **changes: Any) -> ArmConfig:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of every field."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ArmConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error. A record without
        ``kv_factor`` or ``ee_offset`` (written before they existed) reads 1 and (0, 0, 0),
        what it trained with."""
        if isinstance(data, dict):
            data = {"kv_factor": 1.0, "ee_offset": (0.0, 0.0, 0.0), **data}
        return cls(**config_fields(cls, data, "arm config", ArmConfigError))


@dataclass(frozen=True)
class ResolvedArm:
    """An arm config with every default filled in from its URDF.

    Attributes:
        config: the config as given (empty fields stay empty: it is what a run saves).
        model: the parsed URDF.
        ee_link: the end-effector link.
        joints: the actuated joints, base to wrist, ``n`` of them (5 to 7).
        home_qpos: home joint angles (rad), ``(n,)``.
        ft_joint: the fixed F/T joint, or "" when the reading is taken at the last arm joint.
        ft_link: the link whose subtree is the tool the F/T reading weighs.
    """

    config: ArmConfig
    model: RobotModel
    ee_link: str
    joints: tuple[Joint, ...]
    home_qpos: tuple[float, ...]
    ft_joint: str
    ft_link: str

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Names of the actuated joints, base to wrist."""
        return tuple(j.name for j in self.joints)


def load_arm(source: str | Path | ArmConfig | None) -> ArmConfig:
    """An :class:`ArmConfig` from a URDF path, an arm file (.toml/.json), a config or None.

    Raises:
        ArmConfigError: an arm file that cannot be parsed, has unknown keys, values of the
            wrong type, or a ``urdf`` that is not a file.
        FileNotFoundError: a path that does not exist (an :class:`~mjx_arm.inputs.InputError`).
        InputFileError: a path that is a folder or cannot be read.
    """
    if source is None:
        return ArmConfig()
    if isinstance(source, ArmConfig):
        return source
    path = Path(source).expanduser()
    if not path.exists() and str(source) in shipped_arm_names():
        path = assets_dir() / f"{source}.urdf"
    if not path.exists():
        raise MissingInputError(
            f"arm {str(source)!r}: no such URDF or arm file; give a path, or a shipped arm: "
            + ", ".join(shipped_arm_names())
        )
    if path.suffix.lower() not in ARM_FILE_SUFFIXES:
        return ArmConfig(urdf=str(require_file(path, "arm URDF").resolve()))
    text = read_text(path, "arm file")
    try:
        data = tomllib.loads(text) if path.suffix.lower() == ".toml" else json.loads(text)
        if isinstance(data, dict):
            data = {"kv_factor": 0.0, "ee_offset": (), **data}  # a file derives what it omits
        arm = ArmConfig.from_dict(data)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError, RecursionError) as err:
        raise ArmConfigError(f"{path}: not a valid arm file: {err}") from err
    except ArmConfigError as err:
        raise ArmConfigError(f"{path}: {err}") from err
    return arm.replace(urdf=_arm_file_urdf(arm.urdf, path)) if arm.urdf else arm


def shipped_arm_names() -> tuple[str, ...]:
    """The short names ``--arm`` takes for the arms in ``assets/`` (their URDFs' stems:
    ``ur5e``, ``ur5e_gripper``, ...; the scene's table and box are not arms)."""
    return tuple(sorted(p.stem for p in assets_dir().glob("*.urdf") if p.stem not in _SCENE_URDFS))


def recorded_arm(record: dict[str, Any], what: str = "the arm was recorded on") -> ArmConfig:
    """The arm a run, a policy or a trajectory recorded (an :meth:`ArmConfig.to_dict` dict),
    its URDF found on this machine: a shipped arm recorded where this package lived
    elsewhere (``assets/NAME.urdf``) is this install's copy.

    Raises:
        ArmConfigError: not an arm config.
        MissingInputError: its URDF is not on this machine (``what``: the message's start).
    """
    arm = ArmConfig.from_dict(record)
    urdf = Path(arm.urdf)
    if urdf.parent.name in ("assets", "_assets") and urdf.stem in shipped_arm_names():
        arm = arm.replace(urdf=str(assets_dir() / urdf.name))
    if not arm.urdf_path.is_file():
        raise MissingInputError(
            f"{what} {arm.urdf}, which is not on this machine; pass the same arm's URDF or "
            "arm file with --arm"
        )
    return arm


def _arm_file_urdf(urdf: str, arm_file: Path) -> str:
    """The absolute path of an arm file's ``urdf`` entry, checked to be a file."""
    if urdf.startswith(PACKAGE_PREFIX):
        package, _, rest = urdf[len(PACKAGE_PREFIX) :].partition("/")
        root = find_package_dir(package, arm_file.resolve(), {})
        if root is None:
            raise ArmConfigError(
                f"{arm_file}: package {package!r} of {urdf!r} not found; add the folder that "
                "holds it to the ROS_PACKAGE_PATH variable"
            )
        resolved = (root / rest).resolve()
    elif Path(urdf).expanduser().is_absolute():
        resolved = Path(urdf).expanduser()
    else:
        resolved = (arm_file.parent / urdf).resolve()
    try:
        found = resolved.is_file()
    except OSError as err:  # a name too long for the filesystem, among others
        raise ArmConfigError(
            f"{arm_file}: urdf {urdf[:80]!r}... cannot be a path ({err.strerror}); give the "
            "URDF's path, relative to the arm file's folder or absolute"
        ) from err
    if not found:
        raise ArmConfigError(
            f"{arm_file}: urdf {urdf!r} ({resolved}) is not a file; give the URDF's path, "
            "relative to the arm file's folder or absolute"
        )
    return urdf if Path(urdf).expanduser().is_absolute() else str(resolved)


def resolve_arm(arm: ArmConfig) -> ResolvedArm:
    """Fill every default of ``arm`` from its URDF and check what was given.

    Raises:
        ArmConfigError: an unknown link or joint, a joint that is not a revolute joint of the
            chain to the end effector, fewer than 5 or more than 7 joints, or a home pose of
            the wrong length or outside the limits.
    """
    path = arm.urdf_path
    model = parse_urdf(path)
    ee_link = arm.ee_link or default_ee_link(model)
    if ee_link not in model.links:
        raise ArmConfigError(
            f"{path}: ee_link {ee_link!r} is not a link; links: {list(model.links)}"
        )
    joints = _joints(model, ee_link, arm.joints, path)
    home = tuple(float(q) for q in arm.home_qpos) or default_home(path, joints)
    _check_home(home, joints, path)
    ft_joint, ft_link = _ft_point(model, joints, arm.ft_joint, ee_link, path)
    return ResolvedArm(arm, model, ee_link, joints, home, ft_joint, ft_link)


def is_shipped(arm: ArmConfig) -> bool:
    """Whether ``arm`` is one of the shipped arms of ``assets/`` as shipped (its own end
    effector and joints)."""
    path = arm.urdf_path
    shipped = path.parent == default_arm_urdf().parent and path.name in SHIPPED_ARMS
    return shipped and not (arm.ee_link or arm.joints)


def default_home(path: Path, joints: tuple[Joint, ...]) -> tuple[float, ...]:
    """The shipped arms' tool-down pose, else the middle of each joint's limits."""
    shipped = path.parent == default_arm_urdf().parent and path.name in SHIPPED_ARMS
    if shipped and len(joints) == len(SHIPPED_HOME_QPOS):
        return SHIPPED_HOME_QPOS
    return tuple(_mid(j) for j in joints)


def _mid(joint: Joint) -> float:
    """Middle of a joint's range (rad); 0 for a continuous or unlimited joint."""
    if joint.type == "continuous" or joint.limit is None:
        return 0.0
    return 0.5 * (joint.limit.lower + joint.limit.upper)


def _joints(
    model: RobotModel, ee_link: str, names: tuple[str, ...], path: Path
) -> tuple[Joint, ...]:
    """The actuated joints: ``names`` checked against the chain, or the whole chain."""
    chain = arm_chain(model, ee_link)
    if names:
        on_chain = {j.name: j for j in chain}
        off = [n for n in names if n not in on_chain]
        if off:
            raise ArmConfigError(
                f"{path}: joints {off} are not revolute joints on the chain to {ee_link!r} "
                f"({[j.name for j in chain]})"
            )
        chain = [on_chain[n] for n in names]
    if not MIN_JOINTS <= len(chain) <= MAX_JOINTS:
        raise ArmConfigError(
            f"{path}: the tasks drive {MIN_JOINTS} to {MAX_JOINTS} arm joints; the chain to "
            f"{ee_link!r} has {len(chain)} ({[j.name for j in chain]}). Pick another ee_link "
            "or name the joints in an arm file."
        )
    return tuple(chain)


def _check_home(home: tuple[float, ...], joints: tuple[Joint, ...], path: Path) -> None:
    if len(home) != len(joints):
        raise ArmConfigError(f"{path}: home_qpos has {len(home)} angles for {len(joints)} joints")
    for q, j in zip(home, joints, strict=True):
        if (
            j.limit is not None
            and j.type == "revolute"
            and not (j.limit.lower - 1e-9 <= q <= j.limit.upper + 1e-9)
        ):
            raise ArmConfigError(
                f"{path}: home angle {q} of {j.name!r} is outside [{j.limit.lower}, "
                f"{j.limit.upper}]"
            )


def _ft_point(
    model: RobotModel, joints: tuple[Joint, ...], ft_joint: str, ee_link: str, path: Path
) -> tuple[str, str]:
    """(F/T joint or "", the root link of the tool the reading weighs)."""
    name = ft_joint or (NAMED_FT_JOINT if NAMED_FT_JOINT in model.joints else "")
    if not name:
        return "", joints[-1].child
    if name not in model.joints:
        raise ArmConfigError(f"{path}: ft_joint {name!r} is not a joint of this URDF")
    joint = model.joints[name]
    if joint.type != "fixed":
        raise ArmConfigError(f"{path}: ft_joint {name!r} must be a fixed joint, not {joint.type}")
    if name not in {j.name for j in model.chain_to(ee_link)}:
        raise ArmConfigError(f"{path}: ft_joint {name!r} is not above ee_link {ee_link!r}")
    if _subtree_mass(model, joint.child) <= 0:
        raise ArmConfigError(
            f"{path}: ft_joint {name!r} weighs no mass (link {joint.child!r} and the links below "
            "it are massless frames, which MuJoCo merges into their parent): name a fixed joint "
            "whose child carries the tool's mass, or leave ft_joint empty to read the wrench at "
            "the last arm joint"
        )
    return name, joint.child


def _subtree_mass(model: RobotModel, root: str) -> float:
    """Total mass (kg) of link ``root`` and every link below it."""
    links, total = {root}, 0.0
    for joint in model.joints_in_tree_order():
        if joint.parent in links:
            links.add(joint.child)
    for name in links:
        inertial = model.links[name].inertial
        total += inertial.mass if inertial is not None else 0.0
    return total
