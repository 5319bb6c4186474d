"""The README's example scene runs as written: as a script through ``ngat.run``, and as a scene
file of ``ngat run`` (which uses ``scene`` and skips the script part)."""

import re
import subprocess
import sys
from pathlib import Path

from ngat.scene import load_scene

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_example_scene_runs(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    code = next(b for b in blocks if "scene = Scene(" in b)
    scene_part, _, script_part = code.partition('if __name__ == "__main__":')
    assert len(scene_part.strip().splitlines()) <= 26
    script = [line.strip() for line in script_part.strip().splitlines()[1:]]
    assert len(script) == 3 and script[0].startswith("result = ngat.run(scene")
    path = tmp_path / "notched_bar.py"
    path.write_text(code)

    scene = load_scene(str(path))  # what `ngat run notched_bar.py` runs
    assert scene.name == "notched-bar"
    assert not (tmp_path / "results").exists()

    subprocess.run([sys.executable, str(path)], cwd=tmp_path, check=True, capture_output=True)
    out = tmp_path / "results" / "notched-bar"
    rows = (out / "energies.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 11
    for name in ("force.png", "energies.png", "v_final.png"):
        assert (out / name).stat().st_size > 10_000, name
