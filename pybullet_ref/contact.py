"""How PyBullet's scene pushes back: compliant table, box and cube contacts, calibrated on
MuJoCo's.

Bullet resolves a contact as a hard constraint: a tool that meets the box or a finger that
lands on the cube is stopped within one physics step, and the wrist reads the whole impulse.
MuJoCo's contacts are soft. Under the default ``solref`` (time constant 0.02 s, damping ratio
1) and ``solimp`` (impedance ``d`` up to 0.95) a contact of effective mass ``m`` answers a
strike like a spring of about ``2.6e3 m`` N/m and a damper of ``100 m`` N s/m, while a steady
push is 95 % carried at once (a static stiffness near ``5e4 m`` N/m). ``m`` is MuJoCo's own
figure for the pair (``body_invweight0``): about 6-9 kg for a tool on the box, 0.1 kg for a
finger on a 0.1 kg cube. Measured over the same trained policies and episode seeds (200
episodes): Lift seed 0 sets its fingers down on the cube at a median peak of 40 N in MuJoCo
and 106 N in rigid PyBullet, a strike in most episodes (success 0.895 against 0.065).

Bullet can give a body a contact stiffness ``k`` (N/m) and damping ``c`` (N s/m)
(``changeDynamics(contactStiffness=, contactDamping=)``); its solver then treats each of the
body's contacts as an implicit spring-damper. Two bodies' values combine as springs in series
and dampers side by side; a body that sets none counts as infinitely stiff, with a damping of
0.1. One spring cannot follow both of MuJoCo's regimes, so the values are calibrated per kind of
body on trained policies (``benchmarks/bench_pybullet_contact.py``, results in
``benchmarks/results/contact/``): the setting whose success rates and median peak wrist forces
sit closest to MuJoCo's.

- ``fixed``, the table and the box (the tool, the fingers and the cube meet them): 4e4 N/m and
  200 N s/m. Over 7 Touch policies of two arms the success rates differ from MuJoCo's by 0.011
  on average (rigid: 0.036) and the median peaks by 7 % (rigid: 17 %).
- ``cube``, the free cube of a gripper task (as stiff against the pads): 3e3 N/m and 100 N s/m.
  Over 5 Lift policies: 0.050 and 12 % (rigid: 0.199 and 13 %); Lift seed 0 succeeds in 0.940.

The arm's own links set nothing, so the arm's contacts with the cube take the cube's values.
These are the shipped arm's values: :mod:`pybullet_ref.tool_contact` scales the table and box
spring and damper by another arm's tool mass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from mjx_arm.inputs import ConfigError


@dataclass(frozen=True)
class Compliance:
    """A body's contact spring (N/m) and damper (N s/m) in Bullet."""

    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        finite = math.isfinite(self.stiffness) and math.isfinite(self.damping)
        if not (finite and self.stiffness > 0.0 and self.damping >= 0.0):
            raise ConfigError(
                f"contact stiffness must be > 0 and damping >= 0 (finite), got "
                f"{self.stiffness}, {self.damping}"
            )

    def dynamics(self) -> dict[str, float]:
        """Keyword arguments for ``changeDynamics``."""
        return {"contactStiffness": self.stiffness, "contactDamping": self.damping}

    @classmethod
    def parse(cls, text: str) -> Compliance | None:
        """``"STIFFNESS:DAMPING"`` (N/m:N s/m), or ``"rigid"`` for None."""
        if text == "rigid":
            return None
        try:
            stiffness, damping = (float(v) for v in text.split(":"))
        except ValueError:
            msg = f'a compliance is "rigid" or STIFFNESS:DAMPING, got {text!r}'
            raise ConfigError(msg) from None
        return cls(stiffness, damping)

    def __str__(self) -> str:
        return f"{self.stiffness:g}:{self.damping:g}"


@dataclass(frozen=True)
class SceneContact:
    """The compliance of each kind of scene body in PyBullet (None: Bullet's rigid contact).

    Attributes:
        fixed: the table and the box.
        cube: the free cube of a gripper task.
    """

    fixed: Compliance | None
    cube: Compliance | None

    @staticmethod
    def dynamics_of(compliance: Compliance | None) -> dict[str, float]:
        """``changeDynamics`` keyword arguments for ``compliance`` (none when rigid)."""
        return {} if compliance is None else compliance.dynamics()

    @classmethod
    def parse(cls, text: str) -> SceneContact:
        """``"rigid"``, ``"soft"`` or ``"FIXED/CUBE"``, each part ``"rigid"`` or
        ``"STIFFNESS:DAMPING"`` (e.g. ``"3e4:300/3e3:100"``)."""
        if text in CONTACTS:
            return CONTACTS[text]
        fixed, _, cube = text.partition("/")
        return cls(Compliance.parse(fixed), Compliance.parse(cube or "rigid"))

    def __str__(self) -> str:
        return "/".join(str(c) if c else "rigid" for c in (self.fixed, self.cube))

    def to_dict(self) -> dict[str, dict[str, float] | None]:
        """JSON-ready: each kind's stiffness and damping, None where rigid."""
        return {
            "fixed": None if self.fixed is None else vars(self.fixed).copy(),
            "cube": None if self.cube is None else vars(self.cube).copy(),
        }


RIGID = SceneContact(None, None)
SOFT = SceneContact(Compliance(4e4, 200.0), Compliance(3e3, 100.0))  # see the module docstring
CONTACTS = {"soft": SOFT, "rigid": RIGID}


def scene_contact(value: SceneContact | str) -> SceneContact:
    """``value`` as a :class:`SceneContact`: itself, a name of :data:`CONTACTS`, or the text
    form of :meth:`SceneContact.parse`."""
    return value if isinstance(value, SceneContact) else SceneContact.parse(value)
