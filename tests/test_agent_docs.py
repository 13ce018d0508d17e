"""The C client of docs/protocol.md, compiled and run against a real agent."""

from __future__ import annotations

import asyncio
import re
import shutil
from pathlib import Path

import pytest
from agent_support import running_agents

DOC = Path(__file__).resolve().parent.parent / "docs" / "protocol.md"


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
async def test_c_client_from_the_docs_drives_a_robot(tmp_path):
    code = re.search(r"<!-- client-c -->\s*```c\n(.*?)```", DOC.read_text(), re.S).group(1)
    assert 15 <= len(code.strip().splitlines()) <= 30
    (tmp_path / "ttp.c").write_text(code)
    cc = await asyncio.create_subprocess_exec("cc", "-o", str(tmp_path / "ttp"), str(tmp_path / "ttp.c"))
    assert await cc.wait() == 0
    async with running_agents(backend="ideal") as agents:
        proc = await asyncio.create_subprocess_exec(
            str(tmp_path / "ttp"), str(agents.ports[0]), "T,T,P,100,100,0;500,100,0",
            stdout=asyncio.subprocess.PIPE,
        )
        out, _ = await asyncio.wait_for(proc.communicate(), 20)
        lines = out.decode().splitlines()
        assert proc.returncode == 0
        assert lines[0] == "HELLO,robot-1,BeBot,1" and lines[1] == "OK,P,2" and lines[-1].startswith("EV,DONE")
