"""The README's example scene runs as written (issue 7: a complete 20-line scene)."""

import re
from pathlib import Path

from ngat.cli import main

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_example_scene_runs(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    scene_code = next(b for b in blocks if "scene = Scene(" in b)
    assert len(scene_code.strip().splitlines()) <= 22
    path = tmp_path / "notched_bar.py"
    path.write_text(scene_code)
    assert main(["run", str(path), "--quiet", "--out", str(tmp_path / "out")]) == 0
    rows = (tmp_path / "out" / "energies.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 11
