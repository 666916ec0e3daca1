"""mjx_arm: train and check 6-DoF arm control policies."""

__version__ = "0.1.0"
