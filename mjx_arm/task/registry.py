"""Tasks by name: the built-in ones, those registered in code, and those of installed packages.

A task is one file holding a :class:`mjx_arm.task.spec.Task` (its config preset, sampling,
success and contact rules). The registry stores where each task lives as an entry-point string,
``"module:ATTRIBUTE"``, and imports the module the first time the task is asked for, so naming a
task (the command line's choices, a config's validation) loads nothing. Other packages add tasks
through the ``mjx_arm.tasks`` entry-point group of their metadata; code adds them with
:func:`register_task` (and removes them with :func:`unregister_task`).
"""

from __future__ import annotations

import importlib
from functools import cache
from importlib.metadata import entry_points
from typing import Any

from mjx_arm.names import TASKS

ENTRY_POINT_GROUP = "mjx_arm.tasks"

# name -> "module:ATTRIBUTE" of the Task object, or the Task object itself once loaded. A
# built-in task NAME is the object NAME.upper() of mjx_arm/task/NAME.py.
_TASKS: dict[str, Any] = {name: f"mjx_arm.task.{name}:{name.upper()}" for name in TASKS}


@cache
def _load_entry_points() -> None:
    """Add the tasks that installed packages declare (once per process)."""
    for point in entry_points(group=ENTRY_POINT_GROUP):
        _TASKS.setdefault(point.name, point.value)


def register_task(task: Any, replace: bool = False) -> Any:
    """Register a :class:`~mjx_arm.task.spec.Task` object under ``task.name``; returns it.

    Raises:
        ValueError: the name is taken and ``replace`` is false.
    """
    _load_entry_points()
    if task.name in _TASKS and not replace and _TASKS[task.name] is not task:
        raise ValueError(f"task {task.name!r} is already registered")
    _TASKS[task.name] = task
    return task


def unregister_task(name: str) -> None:
    """Remove the task registered as ``name`` (one :func:`register_task` added; a built-in
    task's name goes back to its file).

    Raises:
        ValueError: no task has that name.
    """
    if name not in task_names():
        raise ValueError(f"unknown task {name!r}; choose one of {list(task_names())}")
    if name in TASKS:
        _TASKS[name] = f"mjx_arm.task.{name}:{name.upper()}"
    else:
        del _TASKS[name]


def task_names() -> tuple[str, ...]:
    """Every task name, built-in ones first (loads no task module)."""
    _load_entry_points()
    return tuple(_TASKS)


def is_task(name: str) -> bool:
    """Whether ``name`` is a registered task name (exact, lower case)."""
    return name in task_names()


def get_task(name: str) -> Any:
    """The :class:`~mjx_arm.task.spec.Task` registered as ``name``.

    Raises:
        ValueError: no task has that name (the message lists the names).
    """
    entry = _TASKS.get(name)
    if entry is None or isinstance(entry, str):
        if not is_task(name):
            raise ValueError(f"unknown task {name!r}; choose one of {list(task_names())}")
        entry = _TASKS[name]
        if isinstance(entry, str):
            module, _, attribute = entry.partition(":")
            entry = _TASKS[name] = getattr(importlib.import_module(module), attribute)
    return entry
