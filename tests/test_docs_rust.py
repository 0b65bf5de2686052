"""The Rust subscriber in docs/messages.md (moved there from the README) is checked: rustfmt parses
it (a syntax check; building it would need the zenoh crate compiled, minutes on this machine)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.conftest import ROOT


def _rustfmt() -> str | None:
    return shutil.which("rustfmt") or next((str(p) for p in [Path.home() / ".cargo" / "bin" / "rustfmt"] if p.is_file()), None)


@pytest.mark.skipif(_rustfmt() is None, reason="rustfmt is not installed on this machine")
def test_messages_doc_rust_example_parses(tmp_path):
    blocks = re.findall(r"```rust\n(.*?)\n```", (ROOT / "docs" / "messages.md").read_text(encoding="utf-8"), re.S)
    assert blocks, "docs/messages.md has no ```rust example"
    for i, code in enumerate(blocks):
        src = tmp_path / f"example{i}.rs"
        src.write_text(code + "\n")
        r = subprocess.run([_rustfmt(), "--edition", "2021", "--emit", "stdout", str(src)], capture_output=True, text=True,
                           timeout=60, env=dict(os.environ))
        assert r.returncode == 0, r.stderr
    # and a broken one is refused, so the check can fail
    bad = tmp_path / "bad.rs"
    bad.write_text("fn main( {\n")
    assert subprocess.run([_rustfmt(), "--edition", "2021", "--emit", "stdout", str(bad)], capture_output=True, timeout=60).returncode != 0
