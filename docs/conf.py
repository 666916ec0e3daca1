"""Sphinx configuration of the mjx_arm docs (Sphinx with MyST: pages in Markdown).

The build first writes the generated pages: the results pages from ``benchmarks/results/``
(:mod:`gen_results`) and the tables of each task's and preset's settings from the code
(:mod:`gen_reference`). Build with warnings as errors, offline::

    python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE)]

import gen_reference  # noqa: E402
import gen_results  # noqa: E402

gen_results.generate(gen_results.RESULTS, HERE / "results")
gen_reference.generate(HERE / "generated")

project = "mjx_arm"
author = "the mjx_arm authors"
copyright = "2026, the mjx_arm authors"
release = "0.1.0"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "generated", "README.md"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# API reference from the docstrings (Google style). Imports are real: the docs build needs the
# package installed, as the tests do.
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_class_signature = "separated"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # "Attributes:" as fields: NamedTuple fields are documented once

html_theme = "furo"
html_title = "mjx_arm"
html_static_path: list[str] = []
# no network: no intersphinx, no remote images, no analytics
