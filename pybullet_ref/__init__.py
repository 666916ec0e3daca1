from pybullet_ref.env import PybulletArmEnv

__all__ = ["PybulletArmEnv"]
