"""docs/developers.md: every Python block is a complete example that runs, each in a fresh
interpreter (the blocks register plugins, which must not leak into other tests)."""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

import pytest

from _runs import guarded_run

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "developers.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", PAGE.read_text(), re.S | re.M)
TOPICS = ("viscosity law", "particle property", "output format", "geometry", "postprocessor", "composition source",
          "benchmark")
READINGS = ("run's settings",)
"""The examples before the topics: what a contributor reads (## Read a ...)."""


def test_every_topic_has_an_example():
    text = PAGE.read_text()
    for topic in TOPICS:
        assert re.search(rf"^## Add an? {topic}$", text, re.M), topic
    for reading in READINGS:
        assert re.search(rf"^## Read an? {reading}$", text, re.M), reading
    assert len(BLOCKS) == len(READINGS) + len(TOPICS)


@pytest.mark.parametrize("block", BLOCKS, ids=[*READINGS, *TOPICS])
def test_example_runs(block, tmp_path):
    proc = guarded_run([sys.executable, "-c", block], cwd=tmp_path, budget=600,
                       env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1",
                            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])})
    assert proc.returncode == 0, proc.stderr[-4000:]
