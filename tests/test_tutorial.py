"""docs/tutorial.md, run as written: every file it shows is written and every command run, in
order, in a fresh folder beside the repository's models/.

A block ```LANG file=PATH``` is a file to save; a ```console``` block holds commands, one a
line after "$ ". The install command is the one exception: it is not run here, but it must be
the command the CI script runs (so CI runs it).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```\s*$", re.MULTILINE | re.DOTALL)
INSTALL = "python3 -m pip install -e '.[test]'"


def tutorial_steps(text: str) -> list[tuple[str, str, str]]:
    """("file", path, content) and ("run", command, "") in the order the page gives them."""
    steps = []
    for info, body in FENCE.findall(text):
        words = info.split()
        files = [w[len("file="):] for w in words if w.startswith("file=")]
        if files:
            steps.append(("file", files[0], body))
        elif words and words[0] == "console":
            for line in body.splitlines():
                if line.startswith("$ "):
                    steps.append(("run", line[2:].strip(), ""))
    return steps


def test_the_tutorial_installs_the_way_ci_does():
    steps = tutorial_steps((ROOT / "docs" / "tutorial.md").read_text())
    installs = [c for kind, c, _ in steps if kind == "run" and "pip install" in c]
    assert installs == [INSTALL]
    assert INSTALL in (ROOT / ".ci" / "run").read_text().replace(" -q ", " ")  # quiet or not
    assert INSTALL in (ROOT / "README.md").read_text()


def test_every_command_of_the_tutorial_runs(tmp_path, require_gl):
    steps = tutorial_steps((ROOT / "docs" / "tutorial.md").read_text())
    assert sum(kind == "run" for kind, _, _ in steps) >= 6
    (tmp_path / "models").symlink_to(ROOT / "models", target_is_directory=True)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    for kind, what, content in steps:
        if kind == "file":
            path = tmp_path / what
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(content)
            continue
        if what == INSTALL:
            continue
        command = re.sub(r"^python3? ", f"{sys.executable} ", what)
        r = subprocess.run(command, shell=True, cwd=tmp_path, env=env, capture_output=True,
                           text=True, timeout=600)
        assert r.returncode == 0, f"`{what}` failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    # What the page promises is there.
    run = tmp_path / "tutorial" / "run"
    for f in ("chain_0/samples.jsonl", "chain_1/samples.jsonl", "summary.json", "posterior.nc",
              "report/index.html", "report/occupancy.png"):
        assert (run / f).exists(), f
