"""Shared pytest setup: the tools package on sys.path, and the `toolkit` fixture: the binary
is $SDFMESH_TOOLKIT, else <repo>/target/debug/toolkit, built with `cargo build --bin
toolkit` first (cargo does nothing when it is up to date)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parents[1]
REPO = TOOLS.parent
if str(TOOLS) not in sys.path:
    sys.path.insert(0, str(TOOLS))


@pytest.fixture(scope="session")
def toolkit():
    env = os.environ.get("SDFMESH_TOOLKIT")
    if env:
        path = Path(env)
        assert path.is_file(), f"SDFMESH_TOOLKIT={env} does not exist"
        return path
    path = REPO / "target" / "debug" / "toolkit"
    if shutil.which("cargo"):
        r = subprocess.run(["cargo", "build", "--quiet", "--bin", "toolkit"], cwd=REPO,
                           capture_output=True, text=True)
        if r.returncode != 0 and not path.is_file():
            pytest.fail(f"cargo build failed and there is no {path}:\n{r.stderr[-3000:]}")
    assert path.is_file(), f"no toolkit binary at {path}; run cargo build"
    return path
