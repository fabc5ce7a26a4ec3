"""The public API re-exported by ``sppl``: every name resolves, and the package's docstring
example runs as written on the shipped example."""

from __future__ import annotations

from pathlib import Path

import sppl


def test_every_public_name_resolves():
    assert sorted(sppl.__all__) == sorted(set(sppl.__all__))
    for name in sppl.__all__:
        assert getattr(sppl, name) is not None, name


def test_the_docstring_example(root, tmp_path, monkeypatch, require_gl):
    monkeypatch.chdir(root)
    model = sppl.load_model("models/shapes.scn")
    obs = sppl.load_observations("examples/three_shapes/obs")
    result = sppl.run_chain(model, obs, tmp_path / "run", steps=20, seed=0, progress=False)
    assert result.summary["steps_done"] == 20
    assert "objects" in result.summary["map"]
    assert Path(tmp_path / "run" / "samples.jsonl").exists()
