"""Every Python snippet of the README runs as written (in order, in a temporary folder)."""

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_has_a_snippet_per_job():
    assert len(BLOCKS) >= 5


@pytest.mark.parametrize("k", range(len(BLOCKS)))
def test_readme_snippet_runs(k, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    exec(compile(BLOCKS[k], f"README.md snippet {k + 1}", "exec"), {"__name__": "__readme__"})
    assert capsys.readouterr().out.strip()          # every snippet prints what it shows
