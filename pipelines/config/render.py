"""A ``RunConfig`` as an annotated TOML file (``crowdmpc config show``), which loads back to the same config.

Every key is written with a comment (symbol, unit, equation, the paper's Table I value, the command-line
option). A key without a single default (``[controller] controller``, the profile's ``[env]`` conventions,
``[sweep] out`` ...) is written commented out, with an example, while unset; once set it is written as a
value.
"""

from __future__ import annotations

import math
import re
import textwrap
from typing import Any, Final

from pipelines.config.resolve import RunConfig
from pipelines.config.schema import SECTION_BY_NAME, WRITE_ORDER

HEADER = """\
# crowdmpc configuration (TOML), for simulate, sweep and config show:
#   crowdmpc --config run.toml simulate --controller cmpc    (or: crowdmpc simulate --config run.toml ...)
#   crowdmpc --config run.toml sweep --experiment table2 --out runs/table2
#   crowdmpc config show --config run.toml --set mpc.w_coll=1e6    (the effective config)
# Precedence, lowest first: these defaults < this file < --set SECTION.KEY=VALUE (in order) < the command's
# explicit options (--humans 5). A commented-out key is unset: it has no single default (see its comment);
# --set SECTION.KEY=null unsets a key this file sets (--set simulate.plot=null: no figure).
# Values marked "Table I" are the paper's (Le et al., Multi-robot cooperative navigation in crowds).
"""


# What a TOML basic string cannot hold as it is: the quote, the backslash, control characters (TOML allows
# the tab; escaped anyway) and DEL. Surrogates (a path's undecodable bytes, from the command line) have no
# TOML form at all; escaped, they print, and reading the file back refuses them by line and column.
ESCAPED: Final[re.Pattern[str]] = re.compile(r'["\\\x00-\x1f\x7f\ud800-\udfff]')


def toml_value(value: Any) -> str:
    """``value`` as a TOML value: floats keep a decimal point or exponent, strings as TOML basic strings,
    lists inline."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _toml_float(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string. Not ``json.dumps``: it writes a character outside the BMP (an emoji
    in a path) as a UTF-16 surrogate pair, ``\\ud83d\\ude00``, which TOML refuses (no Unicode scalar value);
    here it is itself, and only what TOML cannot hold is escaped."""

    def escape(match: re.Match[str]) -> str:
        char = match[0]
        return "\\" + char if char in '"\\' else f"\\u{ord(char):04x}"

    return '"' + ESCAPED.sub(escape, text) + '"'


def _toml_float(x: float) -> str:
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    short = f"{x:g}"
    text = short if float(short) == x else repr(x)
    if "e" in text:
        mantissa, exponent = text.split("e")
        sign = "-" if exponent.startswith("-") else ""
        text = f"{mantissa}e{sign}{exponent.lstrip('+-').lstrip('0') or '0'}"
    elif "." not in text and "inf" not in text and "nan" not in text:
        text += ".0"
    return text


def render(config: RunConfig) -> str:
    """The whole config as TOML with comments."""
    lines = [HEADER.rstrip("\n")]
    for name in WRITE_ORDER:
        section = SECTION_BY_NAME[name]
        lines += ["", f"[{name}]", *(f"# {line}" for line in textwrap.wrap(section.doc, 108))]
        texts = []
        for key in section.keys:
            value = config.values[name][key.name]
            if value is None:  # unset: commented out, with what it stands for
                # an [env] key the profile fills shows the profile's value; one unset in the simulator too
                # (robot_spacing: the formation's own) its example
                example = getattr(config.env, key.name) if name == "env" else None
                example = key.example if example is None else example
                texts.append(f"# {key.name} = {toml_value(example)}")
            else:
                texts.append(f"{key.name} = {toml_value(value)}")
        width = max(len(text) for text in texts) + 2
        lines += [f"{text:<{width}}# {key.note}" for text, key in zip(texts, section.keys, strict=True)]
    return "\n".join(lines) + "\n"
