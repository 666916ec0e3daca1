"""Robustness tools for the URDF pipeline, not shipped in the wheel: a seeded URDF mutation
generator (:mod:`urdf_fuzz.mutate`) and a harness that runs the pipeline's entry points on the
mutants in a worker process (:mod:`urdf_fuzz.harness`). Used by tests/test_urdf_fuzz.py and
benchmarks/bench_urdf_fuzz.py; run from the repository root."""
