"""The URDF pipeline: validate a URDF, then convert it to an MJX-ready MJCF model."""

from mjx_arm.urdf.convert import ConvertConfig, build_spec, load_model, to_mjcf
from mjx_arm.urdf.errors import ConversionError, UrdfError
from mjx_arm.urdf.model import RobotModel, parse_urdf

__all__ = [
    "ConversionError",
    "ConvertConfig",
    "RobotModel",
    "UrdfError",
    "build_spec",
    "load_model",
    "parse_urdf",
    "to_mjcf",
]
