"""Robustness tools for the command line's inputs, not shipped in the wheel: good inputs built
in seconds without training (:mod:`input_fuzz.corpus`), their generic mutations
(:mod:`input_fuzz.mutate`) and structure-aware hostile ones (:mod:`input_fuzz.hostile`,
:mod:`input_fuzz.hostile_npz`, :mod:`input_fuzz.hostile_onnx`), hypothesis strategies of whole
``mjx-arm`` command lines (:mod:`input_fuzz.cases`), a harness that runs one and judges the
outcome (:mod:`input_fuzz.harness`) and a pool of worker processes under a memory cap that runs
them (:mod:`input_fuzz.pool`). Used by tests/test_input_fuzz.py and
benchmarks/bench_input_fuzz.py; run from the repository root."""
