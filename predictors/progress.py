"""Progress bars for long loops (tqdm), off where Python has no stderr to draw them on."""

from __future__ import annotations

import sys
from typing import Any


def progress_bar(iterable: Any = None, *, show: bool | None, **kwargs: Any) -> Any:
    """``tqdm(iterable, **kwargs)``, drawn when ``show`` (None: on a terminal only, tqdm's ``disable=None``).

    A program started without descriptor 2 (pythonw, a service, ``2>&-``) has ``sys.stderr = None``, and tqdm
    fails at its first write with an AttributeError. crowdmpc's own commands put /dev/null there first
    (``pipelines.commands.standard_output``); a program that uses the library gets no bar instead.
    """
    from tqdm import tqdm

    if kwargs.get("file", sys.stderr) is None:
        show = False
    return tqdm(iterable, disable=None if show is None else not show, **kwargs)
