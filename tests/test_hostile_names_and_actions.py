"""Over-long URDF names are refused before PyBullet reads them; both engines' envs reject the
same malformed actions with the same error and refuse to run after ``close()``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.envs.base import InvalidActionError
from mjx_arm.urdf.errors import UrdfError
from mjx_arm.urdf.findings import MAX_NAME_CHARS
from mjx_arm.urdf.validate import validate

_BOX = '<geometry><box size="0.1 0.1 0.1"/></geometry>'
_INERTIAL = (
    '<inertial><mass value="1"/>'
    '<inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>'
)


def _urdf(tmp_path: Path, link: str = "tip", joint: str = "j1", material: str = "red") -> Path:
    """A two-link, one-joint arm with the given names."""
    body = f"{_INERTIAL}<visual>{_BOX}</visual><collision>{_BOX}</collision>"
    text = f"""<robot name="arm">
<material name="{material}"><color rgba="1 0 0 1"/></material>
<link name="base">{_INERTIAL}<visual>{_BOX}<material name="{material}"/></visual>
<collision>{_BOX}</collision></link>
<link name="{link}">{body}</link>
<joint name="{joint}" type="revolute"><parent link="base"/><child link="{link}"/>
<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/>
<dynamics damping="0.1"/></joint>
</robot>"""
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    return path


_KINDS = ("link", "joint", "material")


@pytest.mark.parametrize("kind", _KINDS)
def test_name_at_limit_loads_in_pybullet(tmp_path: Path, kind: str) -> None:
    path = _urdf(tmp_path, **{kind: "n" * MAX_NAME_CHARS})
    report = validate(path, engine="pybullet", native=False)
    assert report.ok, report.format()
    code = "import sys, pybullet as p; p.connect(p.DIRECT); p.loadURDF(sys.argv[1])"
    run = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, timeout=60)
    assert run.returncode == 0, run.stderr.decode()


@pytest.mark.parametrize("kind", _KINDS)
def test_name_over_limit_is_one_named_error(tmp_path: Path, kind: str) -> None:
    path = _urdf(tmp_path, **{kind: "n" * (MAX_NAME_CHARS + 1)})
    for engine in ("mujoco", "pybullet", "all"):
        report = validate(path, engine=engine)
        assert len(report.errors) == 1, report.format()
        error = report.errors[0]
        assert error.element.startswith(f"<{kind} name=")
        assert f"{MAX_NAME_CHARS + 1} characters" in error.problem
        assert f"the {MAX_NAME_CHARS} this tool accepts" in error.problem


def test_cli_refuses_long_joint_name_before_pybullet(tmp_path: Path) -> None:
    """2,000 characters crashed PyBullet's loader (exit 139); now exit 2 and one error line."""
    path = _urdf(tmp_path, joint="j" * 2000)
    cmd = [sys.executable, "-m", "mjx_arm.cli", "validate", "--engine", "pybullet", str(path)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stdout + run.stderr
    lines = [ln for ln in (run.stdout + run.stderr).splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "<joint name=" in lines[0] and str(MAX_NAME_CHARS) in lines[0]


def test_env_refuses_long_link_name(tmp_path: Path) -> None:
    path = _urdf(tmp_path, link="t" * 2000)
    with pytest.raises(UrdfError, match=f"more than the {MAX_NAME_CHARS}"):
        gym.make("mjx_arm/Touch-v0", engine="pybullet", arm=str(path))


# --------------------------------------------------------------------------- actions


@pytest.fixture(scope="module")
def envs():
    made = {e: gym.make("mjx_arm/Touch-v0", engine=e).unwrapped for e in ("mujoco", "pybullet")}
    for env in made.values():
        env.reset(seed=0)
    yield made
    for env in made.values():
        env.close()


_BAD_ACTIONS = {
    "complex": np.full(6, 0.1 + 0.5j),
    "strings": np.array(["0.1"] * 6),
    "list of strings": ["0.1"] * 6,
    "objects": np.array([0.1] * 6, dtype=object),
    "ragged": [0.1, [0.2, 0.3], 0.4, 0.5, 0.6, 0.7],
    "wrong shape": np.zeros((2, 3)),
    "too short": np.zeros(5),
    "nan": np.array([np.nan, 0, 0, 0, 0, 0]),
}


@pytest.mark.parametrize("name", list(_BAD_ACTIONS))
def test_bad_action_same_named_error_in_both_engines(envs, name: str) -> None:
    messages = []
    for env in envs.values():
        with pytest.raises(InvalidActionError, match=r"^action ") as info:
            env.step(_BAD_ACTIONS[name])
        assert isinstance(info.value, ValueError) and isinstance(info.value, TypeError)
        messages.append(str(info.value))
    assert messages[0] == messages[1]


def test_real_actions_still_accepted(envs) -> None:
    for env in envs.values():
        for action in (np.zeros(6, np.float32), [0] * 6, np.ones(6, bool), [0.5] * 6):
            env.step(action)


@pytest.mark.parametrize("engine", ["mujoco", "pybullet"])
def test_closed_env_raises_in_both_engines(engine: str) -> None:
    env = gym.make("mjx_arm/Touch-v0", engine=engine)
    env.reset(seed=0)
    env.close()
    env.close()  # a second close is harmless
    with pytest.raises(gym.error.ClosedEnvironmentError, match=r"reset\(\) called after close"):
        env.reset(seed=0)
    with pytest.raises(gym.error.ClosedEnvironmentError, match=r"step\(\) called after close"):
        env.step(np.zeros(6))
