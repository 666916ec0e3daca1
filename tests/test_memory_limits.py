"""Batches that cannot fit in host memory are refused before allocation, with the estimate, the
available memory and the largest num_envs that fits; the estimate is measured against the RSS
of real batches of the C MuJoCo backend."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import mjx_arm  # noqa: F401  (registers the ids)
from mjx_arm.cli import main
from mjx_arm.envs.backend import (
    InsufficientMemoryError,
    MemoryEstimate,
    available_memory,
    check_memory,
)
from mjx_arm.inputs import InputError
from mjx_arm.names import EXIT_INVALID

# The RSS a batch adds (peak, after reset and 5 steps, beside a 1-env batch that compiled the
# same programs) over the estimate of that batch: measured 1.14 (64 envs), 1.17 (1,024) and
# 1.25 (8,192) on a 2-core x86 host. A run is refused only above the available memory, so an
# estimate low by up to 2x, or high by up to 2x, is the stated tolerance.
RSS_OVER_ESTIMATE = (0.5, 2.0)
PROBE = """
import json, sys
import numpy as np
from mjx_arm.envs.vector import ArmVectorEnv
from mjx_arm.task import task_config

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024

n = int(sys.argv[1])
small = ArmVectorEnv(task_config("reach"), 1, backend="mujoco")
small.reset(seed=0)
for _ in range(3):
    small.step(np.zeros((1, 6)))
base = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # the peak (VmHWM) restarts from the RSS now
env = ArmVectorEnv(task_config("reach"), n, backend="mujoco")
estimate = env.memory_estimate().total(n)
env.reset(seed=0)
for _ in range(5):
    env.step(np.random.default_rng(0).uniform(-1, 1, (n, 6)))
peak = max(status("VmHWM"), status("VmRSS"))
print(json.dumps({"grown": peak - base, "estimate": estimate}))
"""


def test_the_refusal_names_the_estimate_the_available_and_the_largest_batch():
    estimate = MemoryEstimate(fixed=10 * 2**20, per_env=2**20)
    check_memory(estimate, 100, "num_envs", available=2**30)  # 110 MiB of 1 GiB: fits
    with pytest.raises(InsufficientMemoryError) as err:
        check_memory(estimate, 2000, "num_envs", available=2**30)
    text = str(err.value)
    assert "num_envs=2000 needs about 2.0 GiB" in text and "1.0 GiB is available" in text
    assert "the largest num_envs that fits is about 1014" in text
    assert estimate.largest(2**30) == 1014 and estimate.total(1014) <= 2**30
    assert isinstance(err.value, InputError)
    assert 0 < available_memory() < 2**50


def test_make_vec_of_10_to_the_8_envs_is_refused_before_allocation():
    with pytest.raises(InsufficientMemoryError, match=r"num_envs=100000000 needs about \d+"):
        gym.make_vec("mjx_arm/Reach-v0", num_envs=10**8, backend="mujoco")


def test_train_with_a_million_envs_is_refused_with_one_error_line(tmp_path: Path, capsys):
    run_dir = tmp_path / "run"
    argv = ["train", "--run-dir", str(run_dir), "--backend", "mujoco"]
    code = main([*argv, "--set", "num_envs=1048576", "batch_size=1048576"])
    err = capsys.readouterr().err
    assert code == EXIT_INVALID and "Traceback" not in err
    (line,) = [x for x in err.splitlines() if x.startswith("error:")]
    assert "num_envs=1048576" in line and "GiB of host memory" in line
    assert not (run_dir / "checkpoints").exists()


@pytest.mark.slow
@pytest.mark.parametrize("num_envs", [64, 1024, 8192])
def test_the_estimate_matches_the_rss_of_real_batches(num_envs: int):
    out = subprocess.run(
        [sys.executable, "-c", PROBE, str(num_envs)],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    figures = json.loads(out.stdout.strip().splitlines()[-1])
    ratio = figures["grown"] / figures["estimate"]
    low, high = RSS_OVER_ESTIMATE
    assert low <= ratio <= high, figures


# --------------------------------------------------------------------------- mesh side files

# A child that validates URDFs under an address-space limit, each result and the peak resident
# memory a JSON line. Validating a URDF without JAX peaks near 0.5 GB of address space; before
# side files were checked, a glTF buffer or Collada texture on /dev/zero took 3.2-3.4 GB.
MESH_CHILD = """
import contextlib, io, json, resource, sys
limit = int(sys.argv[1])
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
from mjx_arm.cli import main
for path in sys.argv[2:]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = main(["validate", path])
    peak = [int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM")][0]
    print(json.dumps([path, code, out.getvalue(), peak * 1024]), flush=True)
"""
MESH_ADDRESS_SPACE = 2 * 2**30
MESH_PEAK_RSS = 2**30  # what a check may take at most, measured peak about 0.2 GB


def _zero_device(path: Path) -> Path:
    """A character device node at ``path`` that reads like /dev/zero (needs CAP_MKNOD)."""
    import os
    import stat

    try:
        os.mknod(path, stat.S_IFCHR | 0o600, os.makedev(1, 5))
    except PermissionError:
        pytest.skip("creating a device node needs CAP_MKNOD")
    return path


def test_side_files_on_a_zero_device_are_refused_under_an_address_space_limit(tmp_path):
    from test_mesh_side_files import TETRA, collada_with_texture, gltf_box, robot

    for name in ("gltf", "dae", "obj"):
        (tmp_path / name).mkdir()
    _, buffers = gltf_box(tmp_path / "gltf")
    buffers[0].unlink()
    _zero_device(buffers[0])
    collada_with_texture(tmp_path / "dae" / "box.dae", "skin.png")
    _zero_device(tmp_path / "dae" / "skin.png")
    (tmp_path / "obj" / "tetra.obj").write_bytes(b"mtllib side.mtl\n" + TETRA)
    _zero_device(tmp_path / "obj" / "side.mtl")
    meshes = {"gltf": "box.gltf", "dae": "box.dae", "obj": "tetra.obj"}
    paths = [robot(tmp_path / name, mesh, name=name) for name, mesh in meshes.items()]
    argv = [sys.executable, "-c", MESH_CHILD, str(MESH_ADDRESS_SPACE), *map(str, paths)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=180)
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    results = {Path(path).stem: (code, out, peak) for path, code, out, peak in lines}
    assert done.returncode == 0 and len(results) == len(meshes), done.stderr[-2000:]
    device = "which is a character device, not a regular file"
    gltf, obj, dae = results["gltf"], results["obj"], results["dae"]
    assert gltf[0] == 2 and f"names buffer 'gltf_buffer_0.bin', {device}" in gltf[1], gltf[1]
    assert obj[0] == 2 and f"names material library 'side.mtl', {device}" in obj[1], obj[1]
    assert dae[0] == 0, dae[1]  # the converter reads no texture, PyBullet neither
    assert all(peak < MESH_PEAK_RSS for _, _, peak in results.values()), results
