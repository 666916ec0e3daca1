"""Robustness tools for the command line's inputs, not shipped in the wheel: good inputs built
in seconds without training (:mod:`input_fuzz.corpus`), their mutations (:mod:`input_fuzz.mutate`),
hypothesis strategies of whole ``mjx-arm`` command lines (:mod:`input_fuzz.cases`) and an
in-process harness that runs them and checks the outcome (:mod:`input_fuzz.harness`). Used by
tests/test_input_fuzz.py and benchmarks/bench_input_fuzz.py; run from the repository root."""
