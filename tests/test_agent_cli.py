"""``twb agent`` as a real process: ports on stderr, a path over TCP, the tracker CSV, Ctrl-C."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from contract.protocol import encode_path, encode_place

TWB = Path(sys.executable).with_name("twb")
START_TIMEOUT_S = 20.0


def _lines(sock: socket.socket):
    buf = b""
    while True:
        while b"\n" not in buf:
            chunk = sock.recv(65536)
            if not chunk:
                return
            buf += chunk
        line, buf = buf.split(b"\n", 1)
        yield line.decode()


@pytest.mark.slow
def test_agent_process_drives_writes_csv_and_stops_on_ctrl_c(tmp_path):
    csv = tmp_path / "poses.csv"
    proc = subprocess.Popen(
        [str(TWB), "agent", "--port", "0", "--backend", "ideal", "--time-scale", "max", "--robots", "2",
         "--robot-id", "bb", "--tracker-csv", str(csv)],
        stderr=subprocess.PIPE, text=True,
    )
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        ports = None
        while ports is None:
            assert time.monotonic() < deadline, "twb agent did not report its ports"
            line = proc.stderr.readline()
            assert line, f"twb agent exited early with {proc.poll()}"
            m = re.search(r"ports \[(\d+), (\d+)\]", line)
            if m:
                ports = [int(m.group(1)), int(m.group(2))]
        with socket.create_connection(("127.0.0.1", ports[1]), timeout=10) as s:
            lines = _lines(s)
            assert next(lines) == "HELLO,bb-2,BeBot,1"
            s.sendall((encode_place((0.2, 0.2, 0.0)) + "\n").encode())
            assert next(lines) == "OK,I"
            s.sendall((encode_path([(0.2, 0.2, 0.0), (0.6, 0.2, 0.0)]) + "\n").encode())
            for line in lines:
                if line.startswith(("EV,DONE", "EV,FAIL")):
                    break
            assert line.startswith("EV,DONE")
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=15) in (0, 130)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    rows = (tmp_path / "poses-bb-2.csv").read_text().splitlines()
    assert rows[0] == "t,x,y,theta" and len(rows) > 20
    t, x, y, a = (float(v) for v in rows[-1].split(","))
    assert abs(x - 0.6) < 0.03 and abs(y - 0.2) < 0.03


@pytest.mark.parametrize("args, message", [
    (["--time-scale", "0"], "--time-scale"),
    (["--robots", "5", "--world", "shared"], "4 sub-fields"),
    (["--server", "http://127.0.0.1:9"], "--token"),
    (["--control-key", "short"], "control_key"),
    (["--server", "http://127.0.0.1:9", "--token", "t", "--control-key", "x" * 20], "--control-key is for standalone"),
])
@pytest.mark.slow
def test_agent_bad_options_fail_with_one_line(twb, args, message):
    r = twb("agent", "--port", "0", *args, env={"TWB_TOKEN": ""} if "--server" in args else None, timeout=30)
    assert r.returncode != 0
    assert message in r.stderr and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
