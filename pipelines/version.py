"""The installed crowdmpc's version: what the CLI prints and every log and sweep records."""

from __future__ import annotations

import functools
from importlib.metadata import PackageNotFoundError, version


@functools.cache
def crowdmpc_version() -> str:
    """Looked up once: importlib.metadata scans every distribution."""
    try:
        return version("crowdmpc")
    except PackageNotFoundError:  # running from a source tree that was not installed
        return "0+unknown"
