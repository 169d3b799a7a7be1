"""The user pages speak of the project as it is now: no title, heading or sentence of README.md or docs/*.md names
an issue or a session (the notebooks under docs/notebook/ keep the history in the words of its time)."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]  # docs/notebook/ is not globbed here
WORDS = re.compile(r"issue [0-9]|[Ss]ession")


def test_the_notebooks_are_left_out_and_the_user_pages_are_in():
    names = {str(page.relative_to(REPO)) for page in PAGES}
    assert {"README.md", "docs/learning.md", "docs/tsp.md"} <= names
    assert not any(name.startswith("docs/notebook/") for name in names)


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(REPO)))
def test_no_user_page_speaks_of_issues_or_sessions(page):
    found = [f"{page.relative_to(REPO)}:{number}: {line.strip()}"
             for number, line in enumerate(page.read_text().splitlines(), 1) if WORDS.search(line)]
    assert not found, "reword for the project as it is now:\n" + "\n".join(found)
