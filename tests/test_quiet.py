"""No foreign prints: MJX's missing-Warp notice and PyBullet's start-up lines stay off the
terminal of a CPU install."""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import pytest

FOREIGN = ("Failed to import warp", "Failed to import mujoco_warp", "argv[0]=", "build time")


def _output_of(code: str) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True
    )
    return done.stdout + done.stderr


@pytest.mark.skipif(importlib.util.find_spec("warp") is not None, reason="warp-lang installed")
def test_mjx_and_brax_import_quietly_without_warp() -> None:
    out = _output_of(
        "import mjx_arm; from mujoco import mjx; import brax.envs.base;"
        "from mujoco.mjx import warp; print('warp installed:', warp.WARP_INSTALLED)"
    )
    assert "warp installed: False" in out  # the module still loads and says so
    assert not [line for line in FOREIGN if line in out], out


@pytest.mark.pybullet
def test_pybullet_env_starts_quietly() -> None:
    out = _output_of(
        "import gymnasium as gym, mjx_arm\n"
        "env = gym.make('mjx_arm/Touch-v0', engine='pybullet')\n"
        "env.reset(seed=0); env.close(); print('done')"
    )
    assert "done" in out
    assert not [line for line in FOREIGN if line in out], out


def test_silenced_block_restores_the_descriptors(capfd: pytest.CaptureFixture[str]) -> None:
    import os

    from pybullet_ref.quiet import STDERR, STDOUT, native_output_silenced

    with native_output_silenced((STDOUT, STDERR)):
        os.write(1, b"hidden out\n")
        os.write(2, b"hidden err\n")
    os.write(1, b"shown\n")
    out, err = capfd.readouterr()
    assert out == "shown\n" and err == ""
