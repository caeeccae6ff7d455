"""Sphinx configuration of the posekit documentation (``sphinx-build -W --keep-going docs docs/_build/html``)."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))        # document this tree, not an installed copy

import posekit  # noqa: E402

project = "posekit"
author = "the posekit authors"
copyright = "the posekit authors, MIT licence"
version = release = posekit.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinxarg.ext",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]
myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 3

# The API reference: what each package's __all__ lists, in source order, from its real home.
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "none"              # the numpydoc sections give types, shapes and units
autodoc_mock_imports = []
numpydoc_show_class_members = False     # autodoc's :members: lists them once
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks = set()

html_theme = "furo"
html_title = f"posekit {release}"
html_static_path = []

# argparse help text is shown as typed: "--out" must not become an en dash
smartquotes = False
