"""Running a mission where a user runs it (its own folder) leaves nothing `git status` shows: pLogger
writes its `LOG_<FILE>_<date>/` folder there, as MOOS-IvP's does, and .gitignore covers all of it."""
from __future__ import annotations

import asyncio
import shutil
import subprocess
from pathlib import Path

import pytest

from helpers import wait_until
from mission_run import MISSIONS, headless, prepare

ROOT = MISSIONS.parent
WARP = 10


def ignored_by_the_repo(relative: Path) -> bool:
    """Whether the repo's .gitignore ignores `relative` (a path under the repo root; need not exist)."""
    return subprocess.run(["git", "check-ignore", "--no-index", "-q", str(relative)], cwd=ROOT).returncode == 0


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="not a git checkout")
def test_s1_alpha_run_leaves_only_ignored_files(tmp_path, free_port):
    port = free_port()
    mission = prepare(MISSIONS / "s1_alpha", "alpha.moos", tmp_path, port, WARP)
    before = {p for p in tmp_path.rglob("*")}
    kinds = (".alog", "._moos", "._bhv", ".xlog")

    async def scenario():
        async with headless(mission, port, WARP, ["NAV_X"]):
            await asyncio.to_thread(wait_until, lambda: all(any(tmp_path.glob(f"LOG_ALPHA_*/*{k}")) for k in kinds),
                                    timeout=20, interval=0.1)
    asyncio.run(scenario())

    made = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")
                  if p not in before and p.is_file() and p.name != "antler.log")   # antler.log: the test's own
    assert {p.suffix for p in made} >= {".alog", ".xlog"} and all(p.parts[0].startswith("LOG_ALPHA_") for p in made)
    shown = [str(p) for p in made if not ignored_by_the_repo(Path("missions") / "s1_alpha" / p)]
    assert shown == [], "git status would show these after a run in missions/s1_alpha"
