"""Robustness tools for the command line's inputs, not shipped in the wheel: good inputs built
in seconds without training (:mod:`input_fuzz.corpus`), their generic mutations
(:mod:`input_fuzz.mutate`), structure-aware hostile ones (:mod:`input_fuzz.hostile`,
:mod:`input_fuzz.hostile_npz`, :mod:`input_fuzz.hostile_onnx`, :mod:`input_fuzz.hostile_mesh`,
:mod:`input_fuzz.hostile_run`) and special files in their place (:mod:`input_fuzz.special`),
hypothesis strategies of whole ``mjx-arm`` command lines (:mod:`input_fuzz.cases`), the files
of a case (:mod:`input_fuzz.files`), a harness that runs one and judges the outcome
(:mod:`input_fuzz.harness`, with the files it must not touch: :mod:`input_fuzz.sentinel`) and a
pool of worker processes under a memory cap that runs them (:mod:`input_fuzz.pool`). Used by
tests/test_input_fuzz.py and benchmarks/bench_input_fuzz.py; run from the repository root."""
