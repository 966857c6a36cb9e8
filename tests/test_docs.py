"""The user documentation: its example runs, and its generated pages match the code."""

import re

import pytest

from .conftest import REPO

DOCS = REPO / "docs"


def _python_blocks(path):
    return re.findall(r"```python\n(.*?)```", path.read_text(), flags=re.S)


@pytest.mark.slow
def test_the_python_api_example_runs(tmp_path, monkeypatch):
    blocks = [b for b in _python_blocks(DOCS / "python_api.md") if not b.startswith("# not run in the tests")]
    assert len(blocks) >= 4
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for block in blocks:
        exec(compile(block, str(DOCS / "python_api.md"), "exec"), namespace)
    assert (tmp_path / "startup.csv").is_file() and (tmp_path / "allan.png").is_file()
