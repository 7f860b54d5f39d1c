"""No path of the development machine in the repository (issue #13 item 2): a clone has none of them."""

from __future__ import annotations

import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# spelled in pieces so that this file does not match itself
FORBIDDEN = ("/" + "work" + "/", "shared" + "/docs", "shared" + "/data")


def _tracked_text_files() -> list[Path]:
    try:
        names = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
        files = [REPO / n for n in names.decode().split("\0") if n]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (an sdist): every file
        built = {".venv", ".git", "build", "__pycache__", "demo-out", ".pytest_cache", ".hypothesis"}
        files = [p for p in REPO.rglob("*") if p.is_file() and not built & set(p.parts)
                 and not any(part.endswith(".egg-info") for part in p.parts)]
    return [f for f in files if f.is_file() and f.suffix not in (".mat", ".png", ".pdf", ".h5", ".so", ".o", ".pyc")]


def test_no_development_machine_path_in_the_repository():
    # Why: "Tests, examples and docstrings read [the development machine's data folder] or cite [its science
    # notes], which a clone does not have"
    hits = []
    for path in _tracked_text_files():
        text = path.read_text(errors="replace")
        hits += [f"{path.relative_to(REPO)}: {bad}" for bad in FORBIDDEN if bad in text]
    assert hits == []


def test_the_science_notes_cited_are_in_the_repository():
    science = (REPO / "docs" / "science.md").read_text()
    for section in range(1, 8):
        assert f"\n## §{section} " in science
    assert "Tjahjowidodo" in science and "Janot" in science
