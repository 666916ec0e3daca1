"""The PyBullet reference engine's row of the engine registry (:mod:`mjx_arm.engines`).

Imported by the registry on its first lookup; it imports nothing of PyBullet itself: each
entry is an import path loaded when that part is used.
"""

from mjx_arm.engines import EngineSpec, register_engine

NAME = "pybullet"

SPEC = register_engine(
    EngineSpec(
        name=NAME,
        label="PyBullet (Gymnasium)",
        env="pybullet_ref.env:PybulletArmEnv",
        env_options=("contact",),
        position_env="mjx_arm.sim2real.position_pybullet:PybulletPositionArmEnv",
        parity="mjx_arm.bench.engines:bullet_engine",
        parity_goal="goal_pybullet_rad",
        grasp="mjx_arm.bench.grasp:run_pybullet",
        parity_causes={
            "joint divergence": (
                "different integrators and contact solvers: PyBullet's drive takes MuJoCo's "
                "implicit servo step but sees the contacts' torque one substep late, and "
                "Bullet's Featherstone integrator and contact solver are not MuJoCo's"
            ),
        },
        urdf_reader="pybullet_ref.urdf_reader:READER",
        urdf_check="pybullet_ref.urdf_check:check_pybullet_load",
        requires="pybullet",
        install_hint="pip install pybullet==3.2.7 (a dependency of mjx_arm)",
    )
)
