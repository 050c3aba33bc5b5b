"""What a page may ask of the node, checked before anything reaches it.

A socket message is JSON ``{"op": "teach", "mode": NAME, "strides": N}``, ``{"op": "cancel"}`` or
``{"op": "save"}`` (to the node's ``adapted_library_path``: a page chooses no file on the leg's
computer). Anything else is refused with a one-line reason (``CommandRefused``).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass

from ..core.errors import GaitEstimatorError
from ..core.kernels import RESERVED_MODE_NAMES
from ..core.teach import check_teach_strides

MAX_MESSAGE_BYTES = 1024
MODE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]{0,39}$")
"""A mode name a page may teach: a letter or digit, then up to 39 of letters, digits, ``_.+-``."""
OPS = {"teach": {"op", "mode", "strides"}, "cancel": {"op"}, "save": {"op"}}


class CommandRefused(ValueError):
    """A socket message that is not a valid command; the text says why (one line)."""


@dataclass(frozen=True)
class Command:
    op: str
    mode: str = ""
    strides: int = 0


def parse_command(text: str | bytes) -> Command:
    """The command in a socket message, or CommandRefused."""
    if not isinstance(text, str):
        raise CommandRefused("binary message")
    if len(text.encode("utf-8", "replace")) > MAX_MESSAGE_BYTES:
        raise CommandRefused(f"message longer than {MAX_MESSAGE_BYTES} bytes")
    try:
        msg = json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        raise CommandRefused("not JSON") from None
    if not isinstance(msg, dict) or msg.get("op") not in OPS:
        raise CommandRefused(f"unknown op (expected one of {', '.join(OPS)})")
    op = msg["op"]
    extra = set(msg) - OPS[op]
    if extra:
        raise CommandRefused(f"{op}: unexpected field(s) {', '.join(sorted(map(str, extra)))[:80]}")
    if op != "teach":
        return Command(op)
    mode, strides = msg.get("mode"), msg.get("strides")
    if not isinstance(mode, str) or not MODE_NAME.match(mode) or mode in RESERVED_MODE_NAMES:
        raise CommandRefused("teach: mode must be 1-40 letters, digits or _.+- (not stand/unknown)")
    try:
        check_teach_strides(strides)
    except GaitEstimatorError as exc:
        raise CommandRefused(f"teach: {exc}") from None
    return Command(op, mode, strides)
