"""The line link between the server (:mod:`.service`) and the sandbox launcher (:mod:`.launch`, :mod:`.supervise`).

The launcher's stdin and stdout carry one message a line.  Every message
kind is named here, and a line is encoded and parsed here only:

==============  ===========================  =====================================================
kind            direction                    line
==============  ===========================  =====================================================
``JSON``        server → launcher (first)    the job, a JSON object (the whole line)
``JSON``        launcher → server (last)     the result, a JSON object (the whole line)
``CONNECTED``   launcher → server            ``C``: the program connected to its robot port
``ROBOT``       launcher → server            ``R <line>``: a program's line for the run's robot
``ROBOT``       server → launcher            ``R <line>``: the robot's line for the program
``END``         server → launcher            ``E <why>``: the run has ended
==============  ===========================  =====================================================

Only a controller program's job (``"relay": true``) uses more than the job and
the result.  Plain Python: the launcher imports it before it enters its namespaces.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from enum import Enum
from typing import Any, Optional, Union

__all__ = ["RUN_ENDED", "LinkKind", "LinkLine", "encode", "parse"]


class LinkKind(Enum):
    """What a link line carries; the value is the line's first character."""

    JSON = "{"  # the job (server -> launcher) or the result (launcher -> server): the line is the JSON object
    CONNECTED = "C"  # launcher -> server: the program connected to its robot port
    ROBOT = "R"  # a robot-port line: the program's for the robot, or the robot's for the program
    END = "E"  # server -> launcher: the run has ended (the text says why)


#: the text of an ``END`` line that says nothing more
RUN_ENDED = "the run ended"


@dataclass(frozen=True)
class LinkLine:
    """One parsed link line: its ``kind`` and ``text`` (a robot line, why the run ended; ``""`` for
    ``CONNECTED``), or for ``JSON`` the decoded object in ``data``."""

    kind: LinkKind
    text: str = ""
    data: Optional[dict[str, Any]] = None


def encode(kind: LinkKind, payload: Union[str, dict[str, Any]] = "") -> bytes:
    """The link line (newline included) of ``kind`` carrying ``payload``: a dict for ``JSON``, else text
    (non-ASCII characters become ``?``; a trailing line break is dropped, one inside would end the line
    early and is refused)."""
    if kind is LinkKind.JSON:
        if not isinstance(payload, dict):
            raise TypeError("a JSON link line carries a dict")
        return json.dumps(payload).encode() + b"\n"
    if not isinstance(payload, str):
        raise TypeError(f"a {kind.name} link line carries text")
    payload = payload.rstrip("\r\n")
    if "\n" in payload or "\r" in payload:
        raise ValueError("a link line's text has no line break")
    if kind is LinkKind.END:
        payload = payload or RUN_ENDED
    head = kind.value.encode()
    return head + (b" " + payload.encode("ascii", "replace") if payload else b"") + b"\n"


def parse(line: Union[bytes, str]) -> Optional[LinkLine]:
    """The message of one link line (with or without its newline), or None for a line that is none
    (garbage, a JSON line that does not decode to an object)."""
    text = line.decode("utf-8", "replace") if isinstance(line, bytes) else line
    text = text.rstrip("\r\n")
    if text.startswith(LinkKind.JSON.value):
        try:
            data = json.loads(text)
        except ValueError:
            return None
        return LinkLine(LinkKind.JSON, data=data) if isinstance(data, dict) else None
    if text == LinkKind.CONNECTED.value:
        return LinkLine(LinkKind.CONNECTED)
    if text.startswith(LinkKind.ROBOT.value + " "):
        return LinkLine(LinkKind.ROBOT, text[2:])
    if text == LinkKind.END.value or text.startswith(LinkKind.END.value + " "):
        return LinkLine(LinkKind.END, text[2:] or RUN_ENDED)
    return None
