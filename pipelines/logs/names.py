"""An episode recording's file name: the episode's scenario and seed, and which episode of that seed it is.

``McapEpisodeRecorder`` (pipelines.logs.recording) names its files so; the review reads the repeat back
(``repeat_of``) to tell a gym loop's episodes of one seed, each its own, from copies of one episode.
"""

from __future__ import annotations

import re

from pipelines.logs.recorder import UNFINISHED_SUFFIX


def episode_filename(scenario: str, seed: int | None, unseeded: int = 0, repeat: int = 0) -> str:
    """The file of an episode: by its seed, or for one no seed drew (a gym episode started from a layout)
    by its number, ``unseeded``. ``repeat``: how many episodes of that seed the recorder was handed before
    this one (a gym loop may reset to one seed again, with other actions), each kept in its own file,
    ``<scenario>_seed<seed:06d>_<repeat>.mcap`` past the first."""
    if seed is None:
        return f"{scenario}_{unseeded:06d}.mcap"
    return f"{scenario}_seed{seed:06d}" + (f"_{repeat}" if repeat else "") + ".mcap"


def repeat_of(name: str, scenario: object, seed: object) -> int:
    """Which episode of ``seed`` the file ``name`` holds, as ``episode_filename`` numbers them: ``k`` for
    ``<scenario>_seed<seed:06d>_<k>.mcap`` (a gym loop that reset to the seed again) or its unfinished file
    (``UNFINISHED_SUFFIX``: a killed loop's last episode), 0 for any other name (the first, or a file named
    otherwise)."""
    if not isinstance(scenario, str) or not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        return 0
    stem = re.escape(episode_filename(scenario, seed).removesuffix(".mcap"))
    match = re.fullmatch(stem + rf"_([1-9]\d*)\.mcap(?:{re.escape(UNFINISHED_SUFFIX)})?", name)
    return int(match.group(1)) if match else 0
