"""A result's title for its heading on the results pages (``gen_results.py``).

The title says what was measured, read from the file's own data (task, preset, arm, policy,
engine); the file's path goes on the line under it. :func:`unique_titles` tells apart results of
one page that would read the same by their file names.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

Json = dict[str, Any]


def _stem(value: Any) -> str:
    return Path(str(value or "?")).stem


def _seeds(data: Json) -> str:
    s, settings = data.get("summary") or {}, data.get("settings") or {}
    arm = f" on {_stem(settings['arm'])}" if settings.get("arm") else ""
    n = s.get("seeds") or len(data.get("seeds") or [])
    return (f"{str(settings.get('task', '?')).capitalize()}{arm}, `--preset "
            f"{settings.get('preset', '?')}`, {n} seed{'s' if n != 1 else ''}")  # fmt: skip


def _transfer(data: Json) -> str:
    return f"Transfer of `{_stem(data.get('policy'))}` ({data.get('task') or '?'})"


def _robustness(data: Json) -> str:
    return f"Robustness of `{_stem(data.get('policy'))}` ({data.get('task', '?')})"


def _failures(data: Json) -> str:
    rows = data.get("rows") or [{}]
    return f"Failures under {rows[0].get('perturbation', '?')} of `{_stem(data.get('policy'))}`"


def _throughput(data: Json) -> str:
    arm = f", arm {data['arm']}" if data.get("arm") else ""
    return f"Steps per second: {data.get('task', '?')}, backend {data.get('backend', '?')}{arm}"


def _parity(data: Json) -> str:
    arm = (data.get("config") or {}).get("arm")
    return f"Engine parity, {f'arm `{_stem(arm)}`' if arm else 'the shipped arm'}"


def _fuzz(data: Json) -> str:
    return "Hostile URDFs" if "by_kind" in data else "Bad command lines"


TITLES: dict[str, Callable[[Json], str]] = {
    "seeds": _seeds,
    "transfer": _transfer,
    "robustness": _robustness,
    "failures": _failures,
    "throughput": _throughput,
    "parity": _parity,
    "cpu_envs": lambda d: "Gymnasium envs on the CPU beside raw physics",
    "fuzz": _fuzz,
    "eval": lambda d: f"Evaluation in {d.get('engine', '?')}",
    "grasp": lambda d: "The gripper's pick in every engine",
    "train": lambda d: "Training: " + ", ".join(
        f"{r.get('task', '?')} `--preset {r.get('preset', '?')}`" for r in d.get("rows") or []),
}  # fmt: skip


def title(rel: str, data: Json, kind: str) -> str:
    """The heading of the result at ``rel`` (its path under the results) of kind ``kind``."""
    make = TITLES.get(kind)
    if make is not None:
        try:
            return make(data)
        except (AttributeError, KeyError, TypeError, ValueError):
            pass
    path = Path(rel)
    if path.stem in ("summary", "comparison", "parity"):
        return f"{path.stem.capitalize()} of `{path.parent.name}`"
    return path.stem.replace("_", " ").capitalize()


def unique_titles(titles: list[str], rels: list[str]) -> list[str]:
    """``titles`` with the file name added to each one that another of the page shares."""
    counts = Counter(titles)
    short = [
        f"{t} ({Path(rel).parent.name}/{Path(rel).stem})" if counts[t] > 1 else t
        for t, rel in zip(titles, rels, strict=True)
    ]
    again = Counter(short)
    return [
        f"{t} ({rel.removesuffix('.json')})" if again[s] > 1 else s
        for t, s, rel in zip(titles, short, rels, strict=True)
    ]
