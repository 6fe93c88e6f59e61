"""The README's teleoperation embedding example runs as written."""

from __future__ import annotations

import pathlib
import re

import pytest

README = pathlib.Path(__file__).parents[2] / "README.md"


def test_the_readme_teleoperation_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    text = README.read_text()
    section = text[text.index("## Teleoperation (seed 004)") :]
    section = section[: section.index("\n## ", 5)]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(blocks) == 1
    exec(compile(blocks[0], "README.md (teleoperation)", "exec"), {"__name__": "readme"})
    assert capsys.readouterr().out == "arm applied sample 104 of 104\n"
