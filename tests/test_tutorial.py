"""docs/tutorial.md, run as written: every file it shows is written and every command run, in
order, in a fresh folder beside the repository's models/.

A block ```LANG file=PATH``` is a file to save; a ```console``` block holds commands, one a
line after "$ ". The install command is the one exception: it is not run here, but it must be
the command the CI script runs (so CI runs it). A command the prose tells the reader to run, in
an inline code span, must be one of the blocks' commands too (or, for the system packages, the
ones the CI script installs).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```\s*$", re.MULTILINE | re.DOTALL)
INSTALL = "python3 -m pip install -e '.[test]'"
# A command to run, in an inline code span: a program and an argument (for sppl, a command
# and an argument: `sppl sample` alone names the command).
INLINE_COMMAND = re.compile(r"`((?:sppl +\S+|python3?|pip|sudo|apt-get) +[^`\s][^`]*)`")


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


def inline_commands(text: str) -> list[str]:
    """Commands in the prose (outside the fenced blocks), in inline code spans."""
    return INLINE_COMMAND.findall(FENCE.sub("", text))


def test_every_command_the_prose_gives_is_run():
    text = (ROOT / "docs" / "tutorial.md").read_text()
    run = {c for kind, c, _ in tutorial_steps(text) if kind == "run"}
    ci = (ROOT / ".ci" / "run").read_text()
    for command in inline_commands(text):
        if command.startswith("sudo apt-get install "):  # the system packages: CI installs them
            packages = command.split()[3:]
            assert all(re.search(rf"\b{re.escape(p)}\b", ci) for p in packages), command
        else:
            assert command in run, f"`{command}` is in the prose but in no console block"


def test_inline_commands_are_found_outside_blocks_only():
    page = ("Run `sppl verify m.scn` and then `sppl export RUN --out FILE`; `sppl sample` alone "
            "names a command.\n\n```console\n$ sppl check `m.scn`\n```\n")
    assert inline_commands(page) == ["sppl verify m.scn", "sppl export RUN --out FILE"]


def run_steps(steps, folder: Path) -> None:
    """Write each file and run each command in ``folder``, in order; AssertionError naming the
    first command that exits non-zero. ``python`` is this interpreter, ``sppl`` its command."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    for kind, what, content in steps:
        if kind == "file":
            path = folder / what
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(content)
            continue
        if what == INSTALL:
            continue
        command = re.sub(r"^python3? ", f"{sys.executable} ", what)
        r = subprocess.run(command, shell=True, cwd=folder, env=env, capture_output=True,
                           text=True, timeout=600, check=False)
        assert r.returncode == 0, f"`{what}` failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"


def test_every_block_of_the_tutorial_is_a_file_or_commands():
    """A command in a block of another kind would be silently left out of the run below."""
    text = (ROOT / "docs" / "tutorial.md").read_text()
    for info, body in FENCE.findall(text):
        words = info.split()
        assert words and (words[0] == "console" or any(w.startswith("file=") for w in words)), (
            f"a ```{info} block the tests would not run:\n{body}")
    console = [body for info, body in FENCE.findall(text) if info.split()[0] == "console"]
    assert all(line.startswith("$ ") for body in console for line in body.splitlines()
               if line.strip()), "a console block holds a line that is not a command"


def test_the_runner_reads_every_command_and_stops_at_a_failing_one(tmp_path):
    page = ("Some text.\n\n```console\n$ echo one > one.txt\n$ echo two > two.txt\n```\n\n"
            "```text file=dir/three.txt\nthree\n```\n\n```console\n$ cat dir/three.txt\n"
            "$ python -c 'raise SystemExit(3)'\n$ echo never > never.txt\n```\n")
    steps = tutorial_steps(page)
    assert [(k, w) for k, w, _ in steps] == [
        ("run", "echo one > one.txt"), ("run", "echo two > two.txt"), ("file", "dir/three.txt"),
        ("run", "cat dir/three.txt"), ("run", "python -c 'raise SystemExit(3)'"),
        ("run", "echo never > never.txt")]
    with pytest.raises(AssertionError, match="SystemExit"):
        run_steps(steps, tmp_path)
    assert (tmp_path / "two.txt").exists() and (tmp_path / "dir" / "three.txt").exists()
    assert not (tmp_path / "never.txt").exists()


def test_every_command_of_the_tutorial_runs(tmp_path, require_gl):
    steps = tutorial_steps((ROOT / "docs" / "tutorial.md").read_text())
    assert sum(kind == "run" for kind, _, _ in steps) >= 6
    (tmp_path / "models").symlink_to(ROOT / "models", target_is_directory=True)
    run_steps(steps, tmp_path)
    # What the page promises is there.
    run = tmp_path / "tutorial" / "run"
    for f in ("chain_0/samples.jsonl", "chain_1/samples.jsonl", "summary.json", "posterior.nc",
              "report/index.html", "report/occupancy.png", "report/three.min.js",
              "report/predictive_front.png", "report/predictive_side.png"):
        assert (run / f).exists(), f
    assert (tmp_path / "tutorial" / "posterior.nc").stat().st_size > 0  # sppl export's
    page = (run / "report" / "index.html").read_text()
    for part in ("The scene in 3D", "look through", "replay", "Posterior predictive"):
        assert part in page, part  # the parts of the report the tutorial walks through
