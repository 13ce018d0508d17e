"""Send the lines of stdin to HOST:PORT and print every line that comes back: a stand-in for
``nc -q 1 HOST PORT`` on machines without netcat.

    (echo T,T,I,300,300,0; twb plan --env room --plan A --format ttp; sleep 4) | python examples/send_lines.py 127.0.0.1 5555

Like ``nc -q 1`` it quits one second after the end of its input, which closes the connection
(a robot agent stops a robot whose path's sender is gone: keep the input open while it drives).
"""

from __future__ import annotations

import socket
import sys
import threading
import time

LINGER_S = 1.0  # seconds to wait for replies after the end of the input (nc -q 1)


def print_replies(sock: socket.socket) -> None:
    """Copy what the peer sends to stdout, line by line, until it closes."""
    for line in sock.makefile("r", encoding="ascii", errors="replace", newline="\n"):
        sys.stdout.write(line)
        sys.stdout.flush()


def main(argv: list[str]) -> int:
    """Connect, copy stdin to the socket and the socket to stdout; 2 on bad usage, 1 if it cannot connect."""
    if len(argv) != 3:
        print(f"usage: {argv[0]} HOST PORT  (lines from stdin)", file=sys.stderr)
        return 2
    try:
        sock = socket.create_connection((argv[1], int(argv[2])), timeout=10)
    except OSError as exc:
        print(f"cannot connect to {argv[1]}:{argv[2]}: {exc}", file=sys.stderr)
        return 1
    with sock:
        sock.settimeout(None)
        threading.Thread(target=print_replies, args=(sock,), daemon=True).start()
        for line in sys.stdin:
            sock.sendall(line.encode("ascii"))
        time.sleep(LINGER_S)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
