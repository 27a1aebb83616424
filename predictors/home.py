"""The user's home directory, for the default locations under it (the user zoo, the cache) and a "~".

Not ``Path.home()`` nor ``expanduser``: both take an empty ``$HOME`` (``env HOME= crowdmpc``) for "/", so a
run as root wrote its cache into /.cache/crowdmpc, and a relative ``$HOME`` for a folder of the current
directory, a location that changed with it. A ``$HOME`` that is no absolute path is passed over as an unset
one is, for the password database's home. (``mpc.cache_location`` keeps a copy of ``home_dir``: mpc imports
nothing of predictors.)
"""

from __future__ import annotations

import os
import pwd
from pathlib import Path

from predictors.errors import PredictorError


def home_dir(what: str, remedy: str) -> Path:
    """``$HOME`` when it is an absolute path, else the user's home in the password database; a one-line
    PredictorError "cannot find the home directory for ``what`` ...; ``remedy``" when neither is one."""
    home = os.environ.get("HOME")
    if home and Path(home).is_absolute():
        return Path(home)
    try:
        entry = pwd.getpwuid(os.getuid()).pw_dir
    except KeyError:
        entry = ""
    if not Path(entry).is_absolute():  # no password entry, or one without a home
        raise PredictorError(
            f"cannot find the home directory for {what} (no absolute $HOME, and none in the password "
            f"database); {remedy}"
        )
    return Path(entry)


def expand_home(value: str, variable: str) -> Path:
    """The path ``value`` of the variable or setting ``variable`` with a leading ``~`` expanded as a shell
    does; ``~user`` is that user's home in the password database (a PredictorError when there is none). No
    shell expands a quoted ``CROWDMPC_ZOO="~/zoo"`` (an env file, docker -e) nor a config file's value: they
    made a folder named "~" in the current directory."""
    if value == "~" or value.startswith("~/"):
        home = home_dir(f"{variable} {value}", f"set {variable} to an absolute path")
        return home / value[2:].lstrip("/")  # "~//x": home / "/x" would be /x
    try:
        return Path(value).expanduser()  # ~user/...: the password database, never $HOME
    except RuntimeError:
        tilde = value.split("/")[0]
        raise PredictorError(
            f"{variable} {value}: no user {tilde[1:]!r} here, so {tilde} names no home"
        ) from None
