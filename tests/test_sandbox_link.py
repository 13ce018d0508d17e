"""The line link between the server and the sandbox launcher: every message kind encodes and parses back."""

import pytest

from server.sandbox.link import RUN_ENDED, LinkKind, LinkLine, encode, parse


@pytest.mark.parametrize("kind, payload, line", [
    (LinkKind.CONNECTED, "", b"C\n"),
    (LinkKind.ROBOT, "T,T,V,100,0", b"R T,T,V,100,0\n"),
    (LinkKind.ROBOT, "PO,300,300,0,1.5\n", b"R PO,300,300,0,1.5\n"),  # a line's own newline is not doubled
    (LinkKind.END, "watchdog", b"E watchdog\n"),
    (LinkKind.END, "", b"E " + RUN_ENDED.encode() + b"\n"),
    (LinkKind.JSON, {"relay": True, "argv": ["x"]}, b'{"relay": true, "argv": ["x"]}\n'),
])
def test_every_kind_encodes_to_one_line_and_parses_back(kind, payload, line):
    assert encode(kind, payload) == line
    msg = parse(line)
    assert msg is not None and msg.kind is kind
    if kind is LinkKind.JSON:
        assert msg.data == payload
    else:
        assert msg.text == (payload.rstrip("\n") or (RUN_ENDED if kind is LinkKind.END else ""))


def test_a_bare_end_and_text_lines_parse_as_before():
    assert parse("E") == LinkLine(LinkKind.END, RUN_ENDED)
    assert parse(b"R EV,DONE,1.0\r\n") == LinkLine(LinkKind.ROBOT, "EV,DONE,1.0")
    assert parse("R caf\u00e9".encode()) == LinkLine(LinkKind.ROBOT, "caf\u00e9")


@pytest.mark.parametrize("line", [b"", b"hello", b"{not json", b"[1, 2]", b"Rx", b"CONNECTED", b"Ever"])
def test_garbage_is_no_message(line):
    assert parse(line) is None


def test_what_cannot_be_one_line_is_refused():
    with pytest.raises(ValueError, match="no line break"):
        encode(LinkKind.ROBOT, "T,T,S\nT,T,V,0,0")
    with pytest.raises(TypeError):
        encode(LinkKind.JSON, "{}")
    with pytest.raises(TypeError):
        encode(LinkKind.ROBOT, {"a": 1})
    assert encode(LinkKind.ROBOT, "caf\u00e9") == b"R caf?\n"
