"""``mjx-arm bench``: the engine comparisons a user runs on an arm or a policy (``parity``,
``grasp``, ``transfer``, ``robustness``, ``seeds``); product code, as ``mjx-arm eval`` is.

The project's own performance measurements are scripts under ``benchmarks/``, not this package
(``benchmarks/README.md`` states the rule).

- :mod:`~mjx_arm.bench.cli`: the commands' parsers; each writes ``NAME.json`` and ``NAME.md``.
- :mod:`~mjx_arm.bench.engines`: the physics of each engine behind one rollout interface.
- :mod:`~mjx_arm.bench.parity`, :mod:`~mjx_arm.bench.parity_figures`: the engine-parity checks,
  their figures and goals; :mod:`~mjx_arm.bench.grasp`: the gripper's scripted pick.
- :mod:`~mjx_arm.bench.transfer`: one policy evaluated in every engine.
- :mod:`~mjx_arm.bench.robustness`: one policy under perturbations
  (:mod:`~mjx_arm.bench.robustness_config`: which, and their ranges).
- :mod:`~mjx_arm.bench.seeds`: a preset trained over seeds (:mod:`~mjx_arm.bench.seeds_summary`).
- :mod:`~mjx_arm.bench.results`: run metadata, tables and result files.
"""
