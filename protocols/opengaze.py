"""The Gazepoint Open Gaze API (version 2.0), as pure codecs: no sockets, no threads.

Wire format (Open Gaze API by Gazepoint, v2.0, sections 2.2-2.4; docs/opengaze.md): text over TCP (port
4242), one XML element per line, ended by CR LF, every element empty (``/>``), every value a quoted
attribute::

    client:  <GET ID="SCREEN_SIZE" />            <SET ID="ENABLE_SEND_DATA" STATE="1" />
    server:  <ACK ID="SCREEN_SIZE" X="0" Y="0" WIDTH="1920" HEIGHT="1080" />
             <REC CNT="42" FPOGX="0.50124" FPOGY="0.49871" ... />
             <CAL ID="CALIB_START_PT" PT="1" CALX="0.50000" CALY="0.50000" />

Client records are GET and SET; server records ACK (answer), REC (data) and CAL (calibration); NACK
answers a record this server refuses (this emulator's choice: the specification names no error reply),
with an ``ERROR`` token and no spaces in any value, because real clients split records on blanks.

`parse_record` accepts exactly ``<TAG NAME="value" ... />`` (optional blanks around, ``&amp; &lt; &gt;
&quot; &apos;`` in values); `format_record` writes it. `LineSplitter` cuts a byte stream into lines with a
bound on the line length: a longer line is reported once (`OVERLONG`) and skipped to its end.
Numbers from a peer go through `number` / `state` with explicit ranges.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

PORT = 4242
API_VERSION = "2.0"
#: A client line longer than this (bytes, without CR LF) is refused.
MAX_LINE_BYTES = 4096
#: At most this many attributes in one client record.
MAX_ATTRIBUTES = 32
CLIENT_TAGS = ("GET", "SET")
SERVER_TAGS = ("ACK", "NACK", "REC", "CAL")

#: ENABLE_SEND_<x> switches -> the REC attributes they add, in the order a REC carries them.
DATA_FIELDS: dict[str, tuple[str, ...]] = {
    "ENABLE_SEND_COUNTER": ("CNT",),
    "ENABLE_SEND_TIME": ("TIME",),
    "ENABLE_SEND_TIME_TICK": ("TIME_TICK",),
    "ENABLE_SEND_POG_FIX": ("FPOGX", "FPOGY", "FPOGS", "FPOGD", "FPOGID", "FPOGV"),
    "ENABLE_SEND_POG_LEFT": ("LPOGX", "LPOGY", "LPOGV"),
    "ENABLE_SEND_POG_RIGHT": ("RPOGX", "RPOGY", "RPOGV"),
    "ENABLE_SEND_POG_BEST": ("BPOGX", "BPOGY", "BPOGV"),
    "ENABLE_SEND_PUPIL_LEFT": ("LPCX", "LPCY", "LPD", "LPS", "LPV"),
    "ENABLE_SEND_PUPIL_RIGHT": ("RPCX", "RPCY", "RPD", "RPS", "RPV"),
    "ENABLE_SEND_EYE_LEFT": ("LEYEX", "LEYEY", "LEYEZ", "LPUPILD", "LPUPILV"),
    "ENABLE_SEND_EYE_RIGHT": ("REYEX", "REYEY", "REYEZ", "RPUPILD", "RPUPILV"),
    "ENABLE_SEND_PUPILMM": ("LPMM", "LPMMV", "RPMM", "RPMMV"),
    "ENABLE_SEND_CURSOR": ("CX", "CY", "CS"),
    "ENABLE_SEND_BLINK": ("BKID", "BKDUR", "BKPMIN"),
    "ENABLE_SEND_DIAL": ("DIAL", "DIALV"),
    "ENABLE_SEND_GSR": ("GSR", "GSRV"),
    "ENABLE_SEND_HR": ("HR", "HRV"),
    "ENABLE_SEND_HR_PULSE": ("HRP",),
    "ENABLE_SEND_USER_DATA": ("USER",),
}
ENABLE_SEND_DATA = "ENABLE_SEND_DATA"

_TAG = re.compile(r"[A-Z]{2,8}")
_NAME = re.compile(r"[A-Z][A-Z0-9_]{0,39}")
_RECORD = re.compile(r"\s*<([A-Za-z]+)((?:\s+[A-Za-z0-9_]+\s*=\s*\"[^\"<>]*\")*)\s*/>\s*")
_ATTRIBUTE = re.compile(r"([A-Za-z0-9_]+)\s*=\s*\"([^\"<>]*)\"")
_ENTITIES = {"amp": "&", "lt": "<", "gt": ">", "quot": '"', "apos": "'"}
_ENTITY = re.compile(r"&([a-z]+);")
_ESCAPE = str.maketrans({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;"})


class OpenGazeError(ValueError):
    """A client record that cannot be used; `code` is the NACK's ERROR token (no blanks)."""

    def __init__(self, code: str, detail: str = "") -> None:
        super().__init__(f"{code}: {detail}" if detail else code)
        self.code = code


@dataclass(frozen=True)
class Record:
    """One element: its tag (GET, SET, ACK, NACK, REC, CAL) and attributes in order (ID first if any)."""

    tag: str
    attrs: Mapping[str, str] = field(default_factory=dict)

    @property
    def id(self) -> str:
        """The ID attribute ('' if none)."""
        return self.attrs.get("ID", "")


def _unescape(value: str) -> str:
    def entity(m: re.Match[str]) -> str:
        if m.group(1) not in _ENTITIES:
            raise OpenGazeError("BAD_ENTITY", m.group(0))
        return _ENTITIES[m.group(1)]

    out = _ENTITY.sub(entity, value)
    if "&" in _ENTITY.sub("", value):
        raise OpenGazeError("BAD_ENTITY", "a bare '&'")
    return out


def parse_record(line: bytes | str, max_attributes: int = MAX_ATTRIBUTES, max_bytes: int = MAX_LINE_BYTES
                 ) -> Record:
    """The record on one line (CR LF stripped or not); OpenGazeError (NOT_UTF8, MALFORMED, BAD_TAG,
    BAD_NAME, DUPLICATE, TOO_MANY, TOO_LONG, BAD_ENTITY) if it is not exactly one well-formed empty element.
    The limits are a client record's; a client of this server reading CAL records needs larger ones."""
    if len(line) > max_bytes + 2:
        raise OpenGazeError("TOO_LONG", f"{len(line)} bytes")
    if isinstance(line, bytes):
        try:
            line = line.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise OpenGazeError("NOT_UTF8", str(exc)) from None
    m = _RECORD.fullmatch(line)
    if m is None:
        raise OpenGazeError("MALFORMED", "not one element <TAG NAME=\"value\" ... />")
    tag = m.group(1).upper()
    if not _TAG.fullmatch(tag):
        raise OpenGazeError("BAD_TAG", tag)
    attrs: dict[str, str] = {}
    for name, value in _ATTRIBUTE.findall(m.group(2)):
        name = name.upper()
        if not _NAME.fullmatch(name):
            raise OpenGazeError("BAD_NAME", name[:40])
        if name in attrs:
            raise OpenGazeError("DUPLICATE", name)
        if len(attrs) >= max_attributes:
            raise OpenGazeError("TOO_MANY", f"more than {max_attributes} attributes")
        attrs[name] = _unescape(value)
    return Record(tag, attrs)


def format_value(value: object, digits: int = 5) -> str:
    """A value as written in a record: bool -> 0/1, int as is, float with `digits` decimals (never NaN or
    inf: those become 0 and the record's validity flag says so), str escaped."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        v = value if math.isfinite(value) else 0.0
        text = f"{v:.{digits}f}"
        return "0." + "0" * digits if text == "-0." + "0" * digits else text
    return str(value).translate(_ESCAPE)


def format_record(tag: str, attrs: Mapping[str, object] | Iterable[tuple[str, object]] = ()) -> bytes:
    """``<TAG NAME="value" ... />\\r\\n`` as UTF-8 (values through `format_value`)."""
    items = attrs.items() if isinstance(attrs, Mapping) else attrs
    body = "".join(f' {name}="{format_value(value)}"' for name, value in items)
    return f"<{tag}{body} />\r\n".encode()


def ack(record_id: str, **attrs: object) -> bytes:
    """``<ACK ID="record_id" ... />``."""
    return format_record("ACK", {"ID": record_id, **attrs})


def nack(record_id: str, code: str) -> bytes:
    """``<NACK ID="record_id" ERROR="code" />`` (record_id reduced to a safe name)."""
    safe = record_id if _NAME.fullmatch(record_id) else ""
    return format_record("NACK", {"ID": safe, "ERROR": code})


def number(record: Record, name: str, lo: float, hi: float) -> float:
    """Attribute `name` as a finite float in [lo, hi]; OpenGazeError MISSING or BAD_VALUE otherwise."""
    text = record.attrs.get(name)
    if text is None:
        raise OpenGazeError("MISSING", name)
    try:
        value = float(text)
    except ValueError:
        raise OpenGazeError("BAD_VALUE", name) from None
    if not (math.isfinite(value) and lo <= value <= hi):
        raise OpenGazeError("BAD_VALUE", f"{name} outside [{lo}, {hi}]")
    return value


def state(record: Record) -> bool:
    """The STATE attribute, "0" or "1"; OpenGazeError otherwise."""
    text = record.attrs.get("STATE")
    if text is None:
        raise OpenGazeError("MISSING", "STATE")
    if text.strip() not in ("0", "1"):
        raise OpenGazeError("BAD_VALUE", "STATE must be 0 or 1")
    return text.strip() == "1"


OVERLONG = object()  # what `LineSplitter.feed` yields for a line that exceeded MAX_LINE_BYTES


class LineSplitter:
    """Bytes in, complete lines (bytes, without CR LF; empty lines dropped) out; at most `max_line` bytes
    buffered: a longer line yields `OVERLONG` once and is discarded up to its LF."""

    def __init__(self, max_line: int = MAX_LINE_BYTES) -> None:
        self.max_line = max_line
        self._buffer = bytearray()
        self._skipping = False

    @property
    def buffered(self) -> int:
        """Bytes held for an unfinished line."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[bytes | object]:
        """Lines completed by `data` (bytes), and `OVERLONG` where a line was too long."""
        out: list[bytes | object] = []
        start = 0
        while start < len(data):
            end = data.find(b"\n", start)
            piece = data[start:] if end < 0 else data[start:end]
            if self._skipping:
                if end >= 0:
                    self._skipping = False
            elif len(self._buffer) + len(piece) > self.max_line:
                self._buffer.clear()
                out.append(OVERLONG)
                self._skipping = end < 0
            elif end >= 0:
                line = bytes(self._buffer + piece).strip(b"\r \t")
                self._buffer.clear()
                if line:
                    out.append(line)
            else:
                self._buffer += piece
            if end < 0:
                break
            start = end + 1
        return out
