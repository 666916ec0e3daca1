"""The docs read the same on a Git host as in the built site: plain Markdown links to files that
are in the repository, and no MyST roles (a Git host shows ``{doc}`page``` as raw text)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
# written by the docs build, ignored by git: a link into them is broken on a Git host
BUILT = (DOCS / "results", DOCS / "generated", DOCS / "_build")
PAGES = sorted(
    p for p in [*DOCS.rglob("*.md"), ROOT / "README.md"] if not p.is_relative_to(BUILT[0])
    and not p.is_relative_to(BUILT[1]) and not p.is_relative_to(BUILT[2])
)  # fmt: skip
# a role: {name}`target`, not a role's name quoted as code (`{doc}`)
ROLE = re.compile(r"(?<!`)\{(?:doc|ref|download|term|numref|any|py:[a-z]+|mod|func|class|meth)\}`")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _links(page: Path) -> list[str]:
    """Relative link targets of a page (no web addresses, no in-page anchors), code blocks
    left out."""
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
    targets = [t.split("#")[0] for t in LINK.findall(text)]
    return [t for t in targets if t and not re.match(r"[a-z]+:", t)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_uses_no_myst_role(page: Path) -> None:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)
    found = [line for line in text.splitlines() if ROLE.search(line)]
    assert not found, found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_of_a_page_is_a_file_in_the_repository(page: Path) -> None:
    broken = []
    for target in _links(page):
        path = (page.parent / target).resolve()
        if not path.exists() or any(path.is_relative_to(b) for b in BUILT):
            broken.append(target)
    assert not broken, f"{page.name}: {broken}"
