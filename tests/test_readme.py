"""Every Python example in the README and the docs/ pages runs as written (in a scratch dir)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
"""The README and the per-family pages it links (docs/*.md; reproduction folders hold results)."""
BLOCKS = [
    (page.relative_to(ROOT).as_posix(), index, code)
    for page in PAGES
    for index, code in enumerate(re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S))
]


def test_readme_has_python_examples() -> None:
    # the front door keeps two: a game played by hand, and one played by adversary policies
    assert sum(1 for name, _, _ in BLOCKS if name == "README.md") >= 2


def test_readme_links_resolve() -> None:
    # GitHub renders the README with relative links into docs/: each must name a real file
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", README.read_text())
    local = [t for t in targets if "://" not in t]
    assert local, "the README links no docs page"
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README links to missing files: {missing}"


@pytest.mark.parametrize(("page", "index", "code"), BLOCKS, ids=[f"{p}[{i}]" for p, i, _ in BLOCKS])
def test_example_runs(
    page: str, index: int, code: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    compiled = compile(code, f"{page}[python block {index}]", "exec")
    exec(compiled, {"__name__": f"example_{Path(page).stem}_{index}"})


def test_readme_opens_with_the_two_setup_commands() -> None:
    text = README.read_text()
    first_block = re.search(r"```bash\n(.*?)```", text, flags=re.S)
    assert first_block is not None and text.index("```bash") < text.index("## ")
    lines = [line for line in first_block.group(1).splitlines() if line.strip()]
    assert len(lines) == 2
    assert "advgame demo" in lines[0]
    # both install the lock (constraints.txt) with every extra; the second adds the test tools
    assert all("-c constraints.txt" in line for line in lines)
    assert '".[all]"' in lines[0]
    assert '".[all,test]"' in lines[1] and "pytest" in lines[1]
