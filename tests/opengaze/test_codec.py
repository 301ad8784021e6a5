"""eyehil.protocols.opengaze: records parse and format exactly; hostile lines raise OpenGazeError with a code."""

from __future__ import annotations

import pytest

from eyehil.protocols.opengaze import (
    MAX_LINE_BYTES,
    OVERLONG,
    LineSplitter,
    OpenGazeError,
    Record,
    format_record,
    format_value,
    nack,
    number,
    parse_record,
    state,
)


def test_round_trip_of_every_tag() -> None:
    for tag in ("GET", "SET", "ACK", "NACK", "REC", "CAL"):
        attrs = {"ID": "SCREEN_SIZE", "X": "0", "WIDTH": "1920", "USER": 'a "b" <c> & d'}
        line = format_record(tag, attrs)
        assert line.endswith(b" />\r\n")
        assert parse_record(line) == Record(tag, attrs)


def test_what_the_clients_send_parses() -> None:
    # PsychoPy's gazepoint backend puts two blanks before its attributes; PyGaze a blank before "/>"
    assert parse_record(b'<SET ID="CALIBRATE_RESET"  />\r\n') == Record("SET", {"ID": "CALIBRATE_RESET"})
    r = parse_record(b'<SET ID="USER_DATA" VALUE="trial 1" DUR="1" />')
    assert r.id == "USER_DATA" and r.attrs["VALUE"] == "trial 1" and r.attrs["DUR"] == "1"


def test_values_are_written_without_nan_or_negative_zero() -> None:
    assert format_value(float("nan")) == "0.00000" and format_value(-0.0000001) == "0.00000"
    assert format_value(True) == "1" and format_value(12) == "12" and format_value(0.5) == "0.50000"
    assert b" " not in nack("X", "UNKNOWN_ID").strip().split(b'"')[3]  # no blank inside a value


@pytest.mark.parametrize(("line", "code"), [
    (b'<GET ID="SCREEN_SIZE">', "MALFORMED"),  # not an empty element
    (b'<GET ID="SCREEN_SIZE" ', "MALFORMED"),  # unclosed
    (b'<GET ID="A" /><GET ID="B" />', "MALFORMED"),  # two on a line
    (b'<GET ID=SCREEN_SIZE />', "MALFORMED"),  # unquoted
    (b'<GET ID="A" ID="B" />', "DUPLICATE"),
    (b'<GET ID="\xff\xfe" />', "NOT_UTF8"),
    (b'<GET ID="a&b;" />', "BAD_ENTITY"),
    (b'<GET ID="a & b" />', "BAD_ENTITY"),
    (b"<G" + b"E" * 20 + b' ID="X" />', "BAD_TAG"),
    (b'<GET ' + b" ".join(b'A%d="1"' % i for i in range(40)) + b" />", "TOO_MANY"),
    (b'<GET ID="' + b"x" * MAX_LINE_BYTES + b'" />', "TOO_LONG"),
])
def test_hostile_lines_are_refused_with_a_code(line: bytes, code: str) -> None:
    with pytest.raises(OpenGazeError) as info:
        parse_record(line)
    assert info.value.code == code


def test_numbers_and_states_are_range_checked() -> None:
    r = Record("SET", {"ID": "X", "VALUE": "1e308", "X": "nan", "Y": "0.25", "STATE": "2"})
    assert number(r, "Y", 0, 1) == 0.25
    for name in ("VALUE", "X", "MISSING"):
        with pytest.raises(OpenGazeError):
            number(r, name, 0, 10)
    with pytest.raises(OpenGazeError):
        state(r)


def test_line_splitter_bounds_a_line_and_recovers() -> None:
    s = LineSplitter(max_line=16)
    assert s.feed(b'<GET ID="A" />\r\n<GE') == [b'<GET ID="A" />']
    assert s.feed(b'T ID="B" />\r\n') == [b'<GET ID="B" />']
    out = s.feed(b"x" * 40)
    assert out == [OVERLONG] and s.buffered == 0
    assert s.feed(b"y" * 100) == [] and s.buffered == 0  # still skipping that line, nothing kept
    assert s.feed(b'\n<GET ID="C" />\n') == [b'<GET ID="C" />']
