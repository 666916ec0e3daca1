"""The built wheel carries the assets and works from a fresh environment, away from the source tree.

The wheel is built with ``python -m build`` (an isolated build: it fetches the build backend
pinned in pyproject.toml unless pip has it cached) and installed with ``--no-deps`` into a new
venv. The dependencies come from the test venv through a ``.pth`` file, so the install needs no
network and little time; the wheel's own ``mjx_arm`` comes first on ``sys.path``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import textwrap
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ASSETS = (
    "mjx_arm/_assets/ur5e.urdf",
    "mjx_arm/_assets/table.urdf",
    "mjx_arm/_assets/target_box.urdf",
)

# Runs inside the new venv with cwd = tmp_path, so nothing resolves to the source checkout.
SNIPPET = textwrap.dedent(
    """
    import sys
    import sysconfig
    from pathlib import Path

    import gymnasium
    import numpy as np

    import mjx_arm
    from mjx_arm.paths import default_arm_urdf
    from mjx_arm.urdf import load_model, to_mjcf
    from mjx_arm.urdf.validate import validate

    site = Path(sysconfig.get_paths()["purelib"]).resolve()
    assert Path(mjx_arm.__file__).resolve().is_relative_to(site), mjx_arm.__file__
    urdf = default_arm_urdf()
    assert urdf.resolve().is_relative_to(site), (str(urdf), str(site))
    report = validate(urdf, engine="mujoco")
    assert report.ok, report.format()
    assert "<actuator>" in to_mjcf(urdf)
    assert load_model(urdf, scene="touch").nu == 6
    env = gymnasium.make("mjx_arm/Reach-v0", engine="mujoco")
    obs, _ = env.reset(seed=0)
    obs, reward, terminated, truncated, _ = env.step(np.zeros(6, dtype=np.float32))
    assert env.observation_space.contains(obs)
    assert np.isfinite(reward)
    env.close()
    print("WHEEL-OK", urdf)
    """
)


def _run(cmd: list[str], **kwargs) -> subprocess.CompletedProcess:
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300, **kwargs)
    assert result.returncode == 0, f"{cmd}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result


def _clean_env() -> dict[str, str]:
    """The environment without anything that would point Python at the source tree."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel built from the repository root."""
    outdir = tmp_path_factory.mktemp("dist")
    _run(
        [sys.executable, "-m", "build", "--wheel", "--outdir", str(outdir)],
        cwd=REPO,
        env=_clean_env(),
    )
    (path,) = outdir.glob("mjx_arm-*.whl")
    return path


@pytest.mark.slow
def test_wheel_ships_the_assets(wheel: Path):
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    for asset in ASSETS:
        assert asset in names, sorted(n for n in names if "_assets" in n)
    assert "mjx_arm/__init__.py" in names and "pybullet_ref/__init__.py" in names
    assert not any("__pycache__" in n for n in names)


@pytest.mark.slow
def test_wheel_installs_and_runs_in_a_fresh_venv(wheel: Path, tmp_path: Path):
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)])
    python = venv / "bin" / "python"
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(python),
            "install",
            "--no-deps",
            "--no-index",
            "--disable-pip-version-check",
            str(wheel),
        ]
    )
    site = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"])
    here = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (Path(site.stdout.strip()) / "_test_venv_deps.pth").write_text("\n".join(sorted(here)) + "\n")
    result = _run([str(python), "-c", SNIPPET], cwd=tmp_path, env=_clean_env())
    assert "WHEEL-OK" in result.stdout
    assert str(venv) in result.stdout
