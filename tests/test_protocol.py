import itertools
import math
import random
import re

import numpy as np
import pytest

from planners.environment import builtin_names, load_environment
from contract.protocol import (
    MAX_LINE_BYTES,
    MAX_NUMBER_CHARS,
    MAX_POINTS,
    AuthCommand,
    BuildCommand,
    ErrorCode,
    LeaseCommand,
    PathCommand,
    PlaceCommand,
    ProtocolError,
    QueryCommand,
    StopCommand,
    _parse_tuples,
    check_secret,
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
        ("T,T,P,1,nan,3", ErrorCode.SYNTAX, "point 1: 'nan' is not a finite number"),
        ("T,T,P,1,2,inf", ErrorCode.SYNTAX, "point 1: 'inf' is not a finite number"),
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


# --------------------------------------------------------------------------- hardening (linear-time parser)

# The number regex of the parser before the hardening, kept here ONLY as a reference: it backtracks
# badly on long digit runs, so it only ever sees fields of at most 32 characters.
_OLD_NUM_RE = re.compile(r"\s*[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\s*")


def _old_points(payload: str) -> np.ndarray | None:
    """The old rule: the (N, 3) wire values of a point list, or None where it refused the list.

    The old list regex was this number regex joined by "," and ";"; as a number never matches "," or
    ";", matching field by field accepts the same lists (without the list regex's backtracking).
    """
    items = [item.split(",") for item in payload.split(";")]
    if any(len(f) != 3 or any(_OLD_NUM_RE.fullmatch(x) is None for x in f) for f in items):
        return None
    values = np.array(payload.replace(";", ",").split(","), dtype=float).reshape(-1, 3)
    return values if np.isfinite(values).all() else None


def _new_points(payload: str) -> np.ndarray | None:
    try:
        return _parse_tuples(payload, 3, "point", MAX_POINTS)
    except ProtocolError as exc:
        assert exc.code in (ErrorCode.SYNTAX, ErrorCode.RANGE)
        return None


_ALPHABET = "01+-.eE "


def test_number_rule_agrees_with_the_old_one_on_every_short_field():
    """Every string of up to 5 characters of digits, signs, dot, e/E and space: accepted exactly when
    the old regex accepted it, and a refusal names the point and explains the field."""
    for n in range(6):
        for chars in itertools.product(_ALPHABET, repeat=n):
            field = "".join(chars)
            old = _OLD_NUM_RE.fullmatch(field) is not None
            try:
                parse_command(f"T,T,P,{field},1,1")
                new, message = True, ""
            except ProtocolError as exc:
                new, message = False, exc.message
                assert exc.code is ErrorCode.SYNTAX and message.startswith("point 1: ") and "malformed" not in message
            assert new == old, (field, message)


def _valid_number(rng: random.Random) -> str:
    sign = rng.choice(["", "", "+", "-"])
    whole = str(rng.randrange(0, 10 ** rng.randrange(1, 8)))
    frac = str(rng.randrange(0, 10 ** rng.randrange(1, 12))).zfill(rng.randrange(1, 4))
    mantissa = rng.choice([whole, f"{whole}.{frac}", f"{whole}.", f".{frac}", f"{whole}.{frac}"])
    exponent = rng.choice(["", "", "", f"e{rng.randrange(-12, 12)}", f"E+{rng.randrange(0, 40)}", "e-0"])
    pad = " " * rng.choice([0, 0, 0, 1, 3])
    return (pad + sign + mantissa + exponent + pad * rng.randrange(0, 2))[:40]


def _mutate(rng: random.Random, text: str) -> str:
    chars = list(text)
    for _ in range(rng.randrange(1, 4)):
        i = rng.randrange(len(chars) + 1)
        op = rng.randrange(3)
        new = rng.choice("0123456789+-.eE ,;")
        if op == 0:
            chars.insert(i, new)
        elif chars:
            del chars[min(i, len(chars) - 1)]
            if op == 2:
                chars.insert(min(i, len(chars)), new)
    return "".join(chars)


def test_parser_accepts_exactly_the_numbers_the_old_one_did():
    """Seeded corpus of well-formed point lists, and of the same lists mutated: where every number has
    at most 32 characters (the only new limit for such input), the new parser accepts exactly the lists
    the old regex accepted, with bit-identical values."""
    rng = random.Random(20261123)
    compared = accepted = 0
    for _ in range(3000):
        points = rng.randrange(1, 12)
        payload = ";".join(",".join(_valid_number(rng) for _ in range(3)) for _ in range(points))
        for text in (payload, _mutate(rng, payload)):
            if any(len(f.strip()) > MAX_NUMBER_CHARS for f in text.replace(";", ",").split(",")):
                continue
            old, new = _old_points(text), _new_points(text)
            assert (old is None) == (new is None), text
            if old is not None:
                assert np.array_equal(old, new), text
                accepted += 1
            compared += 1
    assert compared > 5000 and accepted > 3000


def _outcome(text: str, width: int) -> tuple[str, object]:
    try:
        return "ok", _parse_tuples(text, width, "point", 1).tolist()
    except ProtocolError as exc:
        return exc.code.value, exc.message


def test_short_items_parse_field_by_field_as_the_vectorised_pass_does(monkeypatch):
    """A single short item (T,T,V, T,T,I, a one-point path) is parsed without the vectorised pass: the same
    values and the same refusal, word for word, on the seeded corpus of valid and mutated items."""
    import contract.protocol as protocol

    rng = random.Random(20261124)
    items = []
    for _ in range(3000):
        width = rng.choice([2, 3])
        item = ",".join(_valid_number(rng) for _ in range(width))
        items += [(item, width), (_mutate(rng, item).replace(";", ","), width)]
    fast = [_outcome(text, width) for text, width in items]
    monkeypatch.setattr(protocol, "_SHORT_ITEM", -1)
    assert [_outcome(text, width) for text, width in items] == fast
    assert sum(kind == "ok" for kind, _ in fast) > 2000 and sum(kind != "ok" for kind, _ in fast) > 1000


@pytest.mark.parametrize("code", [c for c in range(0x20) if c != 0x0A] + [0x7F])
def test_control_characters_are_refused_naming_character_and_column(code):
    line = b"T,T,P,1" + bytes([code]) + b"0,2,3\n"
    with pytest.raises(ProtocolError, match=rf"control character 0x{code:02X} \(\w+\) at column 8") as info:
        parse_command(line)
    assert info.value.code is ErrorCode.SYNTAX


def test_terminators_and_spaces():
    assert isinstance(parse_command(b"T,T,Q\r\n"), QueryCommand)
    assert isinstance(parse_command("T,T,Q"), QueryCommand)
    with pytest.raises(ProtocolError, match=r"0x0D \(CR\) at column 6"):
        parse_command(b"T,T,Q\r\r\n")
    with pytest.raises(ProtocolError, match=r"0x0A \(LF\) at column 6"):
        parse_command("T,T,Q\nT,T,S")
    for sep in (b"\t", b"\x0b", b"\x0c", b"\x1c"):  # only ASCII spaces surround fields
        with pytest.raises(ProtocolError, match="control character"):
            parse_command(b"T,T,P," + sep + b"1,2,3")
    assert len(parse_command(b"T,T,P," + b" " * 100 + b"1" + b" " * 100 + b",2,3").points) == 1


def test_number_length_is_bounded():
    assert parse_command("T,T,P," + "1" * 32 + ",2,3").points[0, 1] == pytest.approx(0.002)
    with pytest.raises(ProtocolError, match="point 1: number '1111.*has 33 characters \\(at most 32\\)"):
        parse_command("T,T,P," + "1" * 33 + ",2,3")
    with pytest.raises(ProtocolError, match="point 2: number .* has 40000 characters"):
        parse_command("T,T,P,1,2,3;" + "1" * 40000 + ",2,3")


@pytest.mark.parametrize("line, message", [
    (b"T,T,P," + b"1" * 40000 + b"x\n", "point 1: expected 3 fields, got 1"),
    (b"T,T,P," + b"1" * 60000 + b"\n", "point 1: expected 3 fields, got 1"),
    (b"T,T,P," + b"1" * (MAX_LINE_BYTES - 7) + b"\n", "point 1: expected 3 fields, got 1"),
    (b"T,T,P,1,1," + b"1" * (MAX_LINE_BYTES - 11) + b"\n", r"point 1: number '1+'\.\.\. has 1048565 characters"),
    (b"T,T,P," + b"1," * ((MAX_LINE_BYTES - 7) // 2) + b"\n", "point 1: expected 3 fields, got 524285"),
    (b"T,T,P," + b"1,1,1;" * 9999 + b"1,1,1" + b"1" * 900000 + b"\n", "point 10000: number"),
    (b"T,T,P," + b"1,1,1;" * 9999 + b"1,1,1-\n", "point 10000: '1-' is not a decimal number"),
    (b"T,T,P," + b"1,1,1;" * 5000 + b"1,1,1x;" + b"1,1,1;" * 4000 + b"1,1,\n", "point 5001: '1x' is not"),
    (b"T,T,P," + b" " * (MAX_LINE_BYTES - 8) + b"\n", "empty path"),
    (b"T,T,B," + b"1e1," * 200000 + b"\n", "too many blocks|block 1: expected 5 fields"),
])
def test_hostile_lines_are_refused_with_the_first_bad_item(line, message):
    with pytest.raises(ProtocolError, match=message) as info:
        parse_command(line)
    assert info.value.code in (ErrorCode.SYNTAX, ErrorCode.RANGE)


def test_random_lines_parse_or_raise_a_protocol_error():
    """Seeded fuzz: random bytes, random protocol-ish text and mutated commands either parse or raise
    ProtocolError; nothing else ever escapes."""
    rng = random.Random(7)
    seeds = [b"T,T,P,100,100,0;500,100,90", b"T,T,B,900,450,60,300,0", b"T,T,I,100,200,-90", b"T,T,Q",
             b"T,T,A,0123456789abcdef", b"T,T,L,0123456789abcdef", b"T,T,S"]
    alphabet = b"0123456789+-.eE ,;TPSQIBAL\t\r\x00\x1f\x7f\xff"
    for i in range(20000):
        kind = i % 3
        if kind == 0:
            line = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40)))
        elif kind == 1:
            line = bytes(rng.choice(alphabet) for _ in range(rng.randrange(0, 60)))
        else:
            line = bytearray(rng.choice(seeds))
            for _ in range(rng.randrange(1, 5)):
                line.insert(rng.randrange(len(line) + 1), rng.choice(alphabet))
            line = bytes(line)
        try:
            parse_command(line, field_size=(1.8, 1.8))
        except ProtocolError as exc:
            assert format_error(exc.code, exc.message).startswith("ERR,")


def test_secrets_for_auth_and_lease():
    key = "k" * 16
    assert parse_command(f"T,T,A,{key}") == AuthCommand(key)
    assert parse_command(f"T,T,A, {key} \r\n") == AuthCommand(key)
    assert parse_command("T,T,L," + "x" * 128) == LeaseCommand("x" * 128)
    assert parse_command("T,T,L") == LeaseCommand(None) == parse_command("T,T,L, ")
    assert parse_command("T,T,A,with inner spaces ok!") == AuthCommand("with inner spaces ok!")
    for bad, message in [("T,T,A", "needs a secret"), ("T,T,A,short", "16 to 128 characters, got 5"),
                         ("T,T,A," + "x" * 129, "got 129"), ("T,T,A," + "x" * 16 + ",y", "without , or ;"),
                         ("T,T,L," + "x" * 16 + ";", "without , or ;")]:
        with pytest.raises(ProtocolError, match=message) as info:
            parse_command(bad)
        assert info.value.code is ErrorCode.SYNTAX
    assert check_secret("0123456789abcdef") == "0123456789abcdef"
    with pytest.raises(ValueError, match="space"):
        check_secret(" 0123456789abcdef")
    with pytest.raises(ValueError, match="printable"):
        check_secret("0123456789abcdef\n")


def test_blocks_must_stay_inside_the_area():
    area = (1.8, 1.8)
    with pytest.raises(ProtocolError, match="block 1 .* reaches beyond the area 0..1800 x 0..1800 mm") as info:
        parse_command("T,T,B,900,900,100000000,100000000,0", field_size=area)
    assert info.value.code is ErrorCode.RANGE
    with pytest.raises(ProtocolError, match="block 2"):  # 100 mm square turned 45 deg reaches 70.7 mm from its centre
        parse_command("T,T,B,100,100,100,100,45;60,60,100,100,45", field_size=area)
    assert len(parse_command("T,T,B,50,150,100,300,0;1799.5,900,1,1800,0", field_size=area).blocks) == 2
    assert len(parse_command("T,T,B,900,900,1801.9,10,0", field_size=area).blocks) == 1  # 1 mm tolerance
    with pytest.raises(ProtocolError, match="reaches beyond"):
        parse_command("T,T,B,900,900,1802.1,10,0", field_size=area)
    assert len(parse_command("T,T,B,900,900,100000000,100000000,0").blocks) == 1  # no area, no check


@pytest.mark.parametrize("name", builtin_names())
def test_builtin_environments_fit_their_area(name):
    env = load_environment(name)
    line = encode_build([(b.x, b.y, b.w, b.h, b.angle) for b in env.blocks])
    assert len(parse_command(line, field_size=env.size).blocks) == len(env.blocks)


def test_moving_obstacles_line():
    from contract.protocol import MovingCommand, encode_moving

    line = encode_moving([((0.04, 0.05, 2, 1.5), [(0.2, 1.2), (0.8, 1.2)]), ((0.03, 0.1, 0, 0), [(0.5, 0.5)])])
    assert line == "T,T,M,40,50,2,1.5,200,1200,800,1200;30,100,0,0,500,500"
    cmd = parse_command(line, field_size=(1.8, 1.8))
    assert isinstance(cmd, MovingCommand) and len(cmd.obstacles) == 2
    np.testing.assert_allclose(cmd.obstacles[0][0], [0.04, 0.05, 2, 1.5])
    np.testing.assert_allclose(cmd.obstacles[0][1], [[0.2, 1.2], [0.8, 1.2]])
    assert parse_command("T,T,M") == MovingCommand(()) and encode_moving([]) == "T,T,M"
    for bad, code, message in (
        ("T,T,M,40,50,2,1.5,200", "SYNTAX", "obstacle 1: expected radius,speed,repeat,delay and 1 to 1000 points"),
        ("T,T,M,40,50,2,1.5,200,1200;0,50,2,1.5,200,1200", "RANGE", "obstacle 2: radius and speed must be > 0"),
        ("T,T,M,40,50,5,1.5,200,1200", "RANGE", "obstacle 1: radius and speed must be > 0, delay >= 0 and repeat 0"),
        ("T,T,M,40,50,2,1.5,200,nan", "SYNTAX", "obstacle 1: 'nan' is not a finite number"),
        ("T,T,M,40,50,2,1.5,200,2000", "RANGE", "obstacle 1 point 1 (200, 2000) mm is outside the field"),
        ("T,T,M," + ";".join(["40,50,0,0,100,100"] * 17), "RANGE", "too many moving obstacles: 17 > 16"),
    ):
        with pytest.raises(ProtocolError) as exc:
            parse_command(bad, field_size=(1.8, 1.8))
        assert exc.value.code.value == code and exc.value.message.startswith(message), exc.value.message
