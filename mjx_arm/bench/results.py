"""What every benchmark result carries: run metadata, a markdown table and the files written.

A result is two files in a topic folder (``benchmarks/results/<topic>/``): ``<name>.json`` (the
numbers and :func:`environment_metadata`, which holds the date and commit) and ``<name>.md`` (the
table printed). No plots, videos or logs beside them: the docs build draws the plots from the
JSON (``benchmarks/README.md`` states the rule), and :func:`check_outside_results` refuses a
picture, a video or a run's log whose folder lies under ``benchmarks/results``.
"""

from __future__ import annotations

import datetime as _dt
import importlib.metadata
import json
import os
import platform
import subprocess
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from mjx_arm.inputs import ConfigError, write_atomic

DEFAULT_PACKAGES = (
    "mujoco",
    "mujoco-mjx",
    "warp-lang",
    "pybullet",
    "gymnasium",
    "numpy",
    "jax",
    "brax",
)
RESULTS_PARTS = ("benchmarks", "results")  # the folder that keeps JSON and Markdown only


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` on Linux, else :func:`platform.processor`)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def usable_cores() -> int:
    """CPU cores this process may run on (affinity mask where available)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def package_versions(packages: Iterable[str] = DEFAULT_PACKAGES) -> dict[str, str | None]:
    """Installed version of each distribution, ``None`` where it is not installed."""
    versions: dict[str, str | None] = {}
    for name in packages:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def git_commit() -> str | None:
    """The checkout's commit (with ``-dirty`` when files changed), or None outside git.

    ``MJX_ARM_GIT_COMMIT``, where set, is taken as it is: for a copy of a checkout whose git
    metadata is not the tree's (a tree copied onto another machine over an older ``.git``).
    """
    given = os.environ.get("MJX_ARM_GIT_COMMIT", "").strip()
    if given:
        return given
    root = Path(__file__).resolve().parents[2]
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return f"{commit}-dirty" if dirty else commit


def accelerator_metadata() -> dict[str, Any]:
    """JAX's backend and devices (kind, count); imports jax, so call it only for JAX runs."""
    import jax

    devices = jax.devices()
    return {
        "backend": jax.default_backend(),
        "device_kind": devices[0].device_kind,
        "device_count": len(devices),
    }


def environment_metadata(
    packages: Iterable[str] = DEFAULT_PACKAGES, accelerator: bool = False
) -> dict[str, Any]:
    """What a result needs to be compared later: machine, software versions, date, commit.

    Args:
        packages: distributions whose versions to record.
        accelerator: also record JAX's devices (imports jax).

    Returns:
        A JSON-ready dict: ``device`` (kind, CPU model, cores), ``python``, ``packages``,
        ``platform``, ``load_average_1min``, ``date`` (UTC, ISO 8601), ``git_commit``.
    """
    meta: dict[str, Any] = {
        "device": {
            "kind": "cpu",
            "cpu_model": cpu_model(),
            "cores": usable_cores(),
            "cpu_count": os.cpu_count(),
        },
        "python": platform.python_version(),
        "packages": package_versions(packages),
        "platform": platform.platform(),
        # 1-minute load average at the start: other work on the machine skews CPU timings
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "git_commit": git_commit(),
    }
    if accelerator:
        acc = accelerator_metadata()
        meta["accelerator"] = acc
        if acc["backend"] != "cpu":
            meta["device"]["kind"] = acc["device_kind"]
    return meta


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A GitHub markdown table; cells are formatted with ``str``."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def save_results(
    name: str, payload: Mapping[str, Any], table_md: str, folder: str | Path
) -> tuple[Path, Path]:
    """Write ``<name>.json`` (``payload``) and ``<name>.md`` (``table_md``) into ``folder``.

    Args:
        name: file stem, e.g. ``"parity"``.
        payload: JSON-serialisable numbers (numpy scalars and arrays are converted).
        table_md: the markdown the benchmark printed.
        folder: where to write (created if missing).

    Returns:
        The paths of the JSON and markdown files.

    Both are written atomically, after the JSON is encoded: a failing or killed benchmark
    leaves the files of an earlier run whole.
    """
    folder = Path(folder)
    json_path, md_path = folder / f"{name}.json", folder / f"{name}.md"
    text = json.dumps(payload, indent=2, default=_json_default) + "\n"
    write_atomic(text.encode(), json_path)
    write_atomic((table_md if table_md.endswith("\n") else table_md + "\n").encode(), md_path)
    return json_path, md_path


def _json_default(value: Any) -> Any:
    """numpy scalars and arrays, paths: the JSON encoder's fallback."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def in_results(folder: str | Path) -> bool:
    """Whether ``folder`` is, or lies inside, a ``benchmarks/results`` folder."""
    parts = Path(folder).resolve().parts
    return any(parts[i : i + 2] == RESULTS_PARTS for i in range(len(parts) - 1))


def check_outside_results(folder: str | Path, what: str, flag: str) -> None:
    """Refuse to write ``what`` (pictures, videos, runs and their logs) into ``folder`` where it
    lies under ``benchmarks/results``, which keeps JSON and Markdown only.

    Raises:
        ConfigError: ``folder`` lies under ``benchmarks/results``; names ``flag``, the fix.
    """
    if in_results(folder):
        raise ConfigError(
            f"{what} would go into {folder}, but benchmarks/results keeps JSON and Markdown only "
            f"(the docs draw the plots from the JSON): give {flag} a folder outside it"
        )


def fmt(value: float | None, spec: str = ".1f") -> str:
    """``value`` formatted with ``spec``, or ``n/a`` for None."""
    return "n/a" if value is None else format(value, spec)


def verdict(ok: bool) -> str:
    """The table's word for a goal met or missed."""
    return "pass" if ok else "MISS"
