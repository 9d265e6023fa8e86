"""docs/python.md's Python blocks, executed in order in one namespace from the checkout's root: local mode on
a temporary store, then the blocks under "## On a server" against a real server on loopback."""
import os

import pytest

from conftest import OPERATOR


def blocks(path):
    """(section heading, code) of every ```python block."""
    out, section, code = [], "", None
    for line in open(path):
        if code is not None:
            if line.startswith("```"):
                out.append((section, "".join(code)))
                code = None
            else:
                code.append(line)
        elif line.startswith("## "):
            section = line[3:].strip()
        elif line.startswith("```python"):
            code = []
    return out


def test_docs_python_md_examples_run(repo, remote_server, tmp_path, monkeypatch, capsys):
    found = blocks(os.path.join(repo, "docs", "python.md"))
    assert len(found) >= 8, found
    monkeypatch.chdir(repo)
    monkeypatch.delenv("VALVEBENCH_SERVER", raising=False)
    monkeypatch.setenv("VALVEBENCH_DB", str(tmp_path / "docs.db"))
    namespace = {}
    for k, (section, code) in enumerate(found):
        if section == "On a server":
            monkeypatch.setenv("VALVEBENCH_SERVER", remote_server)
            monkeypatch.setenv("VALVEBENCH_TOKEN", OPERATOR)
        try:
            exec(compile(code, "docs/python.md block %d (%s)" % (k, section), "exec"), namespace)
        except Exception as e:
            pytest.fail("docs/python.md block %d under '%s' failed: %r\n%s" % (k, section, e, code))
    out = capsys.readouterr().out
    assert "INVALID_ARGUMENT conditions.supply_V: must be > 0, got -1" in out, out
    assert "cancelled" in out
    assert namespace["remote"].server == remote_server
