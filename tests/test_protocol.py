import math

import numpy as np
import pytest

from robot_agent.protocol import (
    MAX_LINE_BYTES,
    MAX_POINTS,
    BuildCommand,
    ErrorCode,
    PathCommand,
    PlaceCommand,
    ProtocolError,
    QueryCommand,
    StopCommand,
    decode_path,
    encode_build,
    encode_path,
    encode_place,
    format_error,
    format_event,
    format_hello,
    format_ok,
    format_status,
    parse_command,
    parse_reply,
)


def test_path_round_trip_in_si_units_with_wire_precision():
    rng = np.random.default_rng(0)
    path = np.column_stack([rng.random((50, 2)) * 1.8, rng.uniform(-math.pi, math.pi, 50)])
    line = encode_path(path)
    assert line.startswith("T,T,P,")
    back = decode_path(line)
    np.testing.assert_allclose(back[:, :2], path[:, :2], atol=0.5e-5)  # 0.01 mm
    dtheta = (back[:, 2] - path[:, 2] + math.pi) % (2 * math.pi) - math.pi
    assert np.abs(dtheta).max() < math.radians(0.006)


def test_wire_units_are_millimetres_and_degrees():
    assert encode_path([[0.3, 1.5, math.pi / 2]]) == "T,T,P,300,1500,90"
    assert encode_path([[0.0, 0.0, -math.pi]]) == "T,T,P,0,0,180"  # wrapped to (-180, 180]
    cmd = parse_command("T,T,P,300,1500,90;600.5,0,-450\r\n")
    assert isinstance(cmd, PathCommand)
    np.testing.assert_allclose(cmd.points, [[0.3, 1.5, math.pi / 2], [0.6005, 0.0, -math.pi / 2]])
    assert encode_place((0.1, 0.2, math.pi)) == "T,T,I,100,200,180"
    assert encode_build([(0.9, 0.45, 0.06, 0.3, 0.0)]) == "T,T,B,900,450,60,300,0"
    assert encode_build([]) == "T,T,B"


def test_spaces_around_fields_are_ignored():
    cmd = parse_command(" T , T , P , 1 , 2 , 3 ; 4,5,6 ")
    np.testing.assert_allclose(cmd.points[:, :2], [[0.001, 0.002], [0.004, 0.005]])


def test_other_commands():
    assert isinstance(parse_command("T,T,S"), StopCommand)
    assert isinstance(parse_command(b"T,T,Q\n"), QueryCommand)
    place = parse_command("T,T,I,100,200,-90")
    assert isinstance(place, PlaceCommand)
    assert place.pose == pytest.approx((0.1, 0.2, -math.pi / 2))
    build = parse_command("T,T,B,900,450,60,300,45;100,100,50,50,0")
    assert isinstance(build, BuildCommand)
    np.testing.assert_allclose(build.blocks[0], [0.9, 0.45, 0.06, 0.3, math.pi / 4])
    assert parse_command("T,T,B").blocks.shape == (0, 5)


@pytest.mark.parametrize(
    "line, code, message",
    [
        ("", ErrorCode.SYNTAX, "empty line"),
        ("   \r\n", ErrorCode.SYNTAX, "empty line"),
        ("hello", ErrorCode.SYNTAX, "commands start with T,T"),
        ("T,T,X", ErrorCode.UNSUPPORTED, "unknown command T,T,X"),
        ("T,T,P", ErrorCode.SYNTAX, "empty path"),
        ("T,T,P,", ErrorCode.SYNTAX, "empty path"),
        ("T,T,P,1,2", ErrorCode.SYNTAX, "point 1: expected 3 fields, got 2"),
        ("T,T,P,1,2,3;4,5,6,7", ErrorCode.SYNTAX, "point 2: expected 3 fields, got 4"),
        ("T,T,P,1,2,3;4,5,", ErrorCode.SYNTAX, r"point 2: '\(empty\)' is not a decimal number"),
        ("T,T,P,1,nan,3", ErrorCode.SYNTAX, "point 1: 'nan' is not finite number"),
        ("T,T,P,1,2,inf", ErrorCode.SYNTAX, "point 1: 'inf' is not finite number"),
        ("T,T,P,1,2,1e999", ErrorCode.SYNTAX, "point 1: numbers must be finite"),
        ("T,T,P,0x10,2,3", ErrorCode.SYNTAX, "'0x10' is not a decimal number"),
        ("T,T,P,1_000,2,3", ErrorCode.SYNTAX, "'1_000' is not a decimal number"),
        ("T,T,P,1 2,2,3", ErrorCode.SYNTAX, "is not a decimal number"),
        ("T,T,S,1", ErrorCode.SYNTAX, "T,T,S takes no arguments"),
        ("T,T,I,1,2,3;4,5,6", ErrorCode.SYNTAX, "exactly one pose"),
        ("T,T,I", ErrorCode.SYNTAX, "T,T,I needs x,y,a"),
        ("T,T,B,1,2,3,4", ErrorCode.SYNTAX, "block 1: expected 5 fields"),
        ("T,T,B,1,2,0,4,0", ErrorCode.RANGE, "block 1: width and height must be > 0"),
        ("T,T,P,1,2,3\u00e9", ErrorCode.SYNTAX, "not ASCII"),
        (b"T,T,P,\xff\xfe", ErrorCode.SYNTAX, "not ASCII"),
    ],
)
def test_malformed_lines_raise_the_right_error(line, code, message):
    with pytest.raises(ProtocolError, match=message) as info:
        parse_command(line)
    assert info.value.code is code
    assert info.value.line().startswith(f"ERR,{code.value},")


def test_limits():
    many = "T,T,P," + ";".join(["1,2,3"] * (MAX_POINTS + 1))
    with pytest.raises(ProtocolError, match="too many points: 10001 > 10000") as info:
        parse_command(many)
    assert info.value.code is ErrorCode.RANGE
    assert len(parse_command("T,T,P," + ";".join(["1,2,3"] * MAX_POINTS)).points) == MAX_POINTS
    with pytest.raises(ProtocolError) as info:
        parse_command(b"T,T,P," + b"1" * MAX_LINE_BYTES)
    assert info.value.code is ErrorCode.TOOLONG
    with pytest.raises(ValueError, match="at most 10000"):
        encode_path(np.zeros((MAX_POINTS + 1, 3)))
    with pytest.raises(ValueError, match="must be finite"):
        encode_path([[0, float("nan"), 0]])


def test_range_check_against_the_field():
    with pytest.raises(ProtocolError, match=r"point 2 \(1900, 100\) mm is outside the field 0..1800 x 0..1800 mm") as info:
        parse_command("T,T,P,100,100,0;1900,100,0", field_size=(1.8, 1.8))
    assert info.value.code is ErrorCode.RANGE
    with pytest.raises(ProtocolError, match="pose 1"):
        parse_command("T,T,I,-5,100,0", field_size=(1.8, 1.8))
    assert parse_command("T,T,P,1800,0,0", field_size=(1.8, 1.8)).points.shape == (1, 3)


def test_replies_and_their_parser():
    assert format_hello("bebot-1", "BeBot") == "HELLO,bebot-1,BeBot,1"
    assert format_ok("P", 12) == "OK,P,12"
    assert format_status("MOVING", (0.3, 0.4, math.pi / 2), 1.25) == "ST,MOVING,300,400,90,1.25"
    assert format_event("WP", 2.5, index=3) == "EV,WP,3,2.5"
    assert format_event("FAIL", 3, reason="COLLISION") == "EV,FAIL,COLLISION,3"
    assert format_error("RANGE", "bad\nthing é") == "ERR,RANGE,bad thing ?"
    with pytest.raises(ValueError):
        format_event("FAIL", 1.0, reason="BORED")
    with pytest.raises(ValueError):
        format_hello("a,b", "BeBot")
    r = parse_reply("EV,FAIL,COLLISION,3.5\n")
    assert (r.kind, r.fields, r.time) == ("EV", ("FAIL", "COLLISION", "3.5"), 3.5)
    assert parse_reply("ERR,SYNTAX,point 1: bad, really").fields == ("SYNTAX", "point 1: bad, really")
    assert parse_reply("OK,S").time is None
    with pytest.raises(ProtocolError):
        parse_reply("WHAT,1")
