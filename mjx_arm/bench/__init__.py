"""Engine benchmarks as commands: ``mjx-arm bench parity`` and ``mjx-arm bench transfer``.

- :mod:`~mjx_arm.bench.engines`: the physics of each engine behind one rollout interface.
- :mod:`~mjx_arm.bench.parity`: the engine-parity checks and their goals.
- :mod:`~mjx_arm.bench.transfer`: one policy evaluated in every engine.
- :mod:`~mjx_arm.bench.results`: run metadata, tables and result files.
"""
