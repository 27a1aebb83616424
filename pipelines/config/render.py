"""A ``RunConfig`` as an annotated TOML file (``crowdmpc config show``), which loads back to the same config.

Every key is written with a comment (symbol, unit, equation, the paper's Table I value, the command-line
option). A key without a single default (``[controller] controller``, the profile's ``[env]`` conventions,
``[sweep] out`` ...) is written commented out, with an example, while unset; once set it is written as a
value.
"""

from __future__ import annotations

import json
import math
import textwrap
from typing import Any

from pipelines.config.resolve import RunConfig
from pipelines.config.schema import SECTION_BY_NAME, WRITE_ORDER

HEADER = """\
# crowdmpc configuration (TOML), for simulate, sweep and config show:
#   crowdmpc --config run.toml simulate --controller cmpc    (or: crowdmpc simulate --config run.toml ...)
#   crowdmpc --config run.toml sweep --experiment table2 --out runs/table2
#   crowdmpc config show --config run.toml --set mpc.w_coll=1e6    (the effective config)
# Precedence, lowest first: these defaults < this file < --set SECTION.KEY=VALUE (in order) < the command's
# explicit options (--humans 5). A commented-out key is unset: it has no single default (see its comment).
# Values marked "Table I" are the paper's (Le et al., Multi-robot cooperative navigation in crowds).
"""


def toml_value(value: Any) -> str:
    """``value`` as a TOML value: floats keep a decimal point or exponent, strings JSON-escaped (valid TOML
    basic strings), lists inline."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _toml_float(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")


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
                example = getattr(config.env, key.name) if name == "env" else key.example
                texts.append(f"# {key.name} = {toml_value(example)}")
            else:
                texts.append(f"{key.name} = {toml_value(value)}")
        width = max(len(text) for text in texts) + 2
        lines += [f"{text:<{width}}# {key.note}" for text, key in zip(texts, section.keys, strict=True)]
    return "\n".join(lines) + "\n"
