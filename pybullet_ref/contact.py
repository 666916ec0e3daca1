"""How PyBullet's scene pushes back: compliant table, box and cube contacts, calibrated on
MuJoCo's.

Bullet resolves a contact as a hard constraint: a tool that meets the box or a finger that
lands on the cube is stopped within one physics step, and the wrist reads the whole impulse.
MuJoCo's contacts are soft. Under the default ``solref`` (time constant 0.02 s, damping ratio
1) and ``solimp`` (impedance ``d`` up to 0.95) a contact of effective mass ``m`` answers a
strike as a spring of about ``2.6e3 m`` N/m and a damper of ``100 m`` N s/m, while a steady
push is 95 % carried at once (a static stiffness near ``5e4 m`` N/m). ``m`` is MuJoCo's own
figure for the two bodies (``body_invweight0``): about 6-9 kg for a tool on the box, 0.1 kg for
a finger on the cube. Measured with the same trained policies and episode seeds: a Lift finger
landing on the cube peaked at a median of 40 N in MuJoCo and 108 N in rigid PyBullet, and the
Touch presses of a UR10 struck above the band in PyBullet only.

Bullet can give a body a contact stiffness ``k`` (N/m) and damping ``c`` (N s/m)
(``changeDynamics(contactStiffness=, contactDamping=)``); its solver then treats each of the
body's contacts as an implicit spring-damper. Two bodies' values combine as springs in series
and dampers side by side, and a body that sets none counts as infinitely stiff with a damping
of 0.1. One spring cannot follow both of MuJoCo's regimes, so the values are calibrated, per
kind of body, on trained policies (``benchmarks/bench_pybullet_contact.py``: success and peak
wrist force beside MuJoCo's on the same episodes):

- ``fixed``: the table and the box, which the tool, the fingers and the cube meet;
- ``cube``: the free cube of a gripper task (its contacts with the pads stay as stiff as this).

The arm's own links set nothing, so contacts between the arm and the cube take the cube's values.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Compliance:
    """A body's contact spring (N/m) and damper (N s/m) in Bullet."""

    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        if not (self.stiffness > 0.0 and self.damping >= 0.0):
            raise ValueError(
                f"contact stiffness must be > 0 and damping >= 0, got {self.stiffness}, "
                f"{self.damping}"
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
            raise ValueError(msg) from None
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
SOFT = SceneContact(Compliance(3e4, 300.0), Compliance(3e3, 100.0))  # see the module docstring
CONTACTS = {"soft": SOFT, "rigid": RIGID}


def scene_contact(value: SceneContact | str) -> SceneContact:
    """``value`` as a :class:`SceneContact`: itself, a name of :data:`CONTACTS`, or the text
    form of :meth:`SceneContact.parse`."""
    return value if isinstance(value, SceneContact) else SceneContact.parse(value)
