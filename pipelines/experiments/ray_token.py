"""A cluster's refusal of the driver's authentication token, at once (pipelines.experiments.ray_join).

A cluster started with token authentication (RAY_AUTH_MODE=token) refuses a driver with a wrong token, or in
another mode, at its first call; Ray 2.60's ``ray.init`` tried again once a second, twenty times
(``Node._init_gcs_client``: RAY_NUM_REDIS_GET_RETRIES), before its ConnectionError, so the sweep's line came
20 s later. Ray has no setting for a refused token alone: ``RAY_gcs_server_port_wait_time_s`` and
``RAY_NUM_REDIS_GET_RETRIES`` shorten every join's tries, a good join's to a head still starting too. So
``check_token`` makes the client ``ray.init``'s first try makes (a GcsClient, milliseconds on a head that
answers) and raises at a refusal of the token only; anything else is left to ``ray.init``, as before.
"""

from __future__ import annotations

import importlib
from typing import Any


def check_token(ray: Any, address: str, refused: Any) -> None:
    """ConnectionError, as ``ray.init`` raises it after its tries, where the cluster at ``address`` (a GCS's
    host:port) refuses this driver's token (``refused(exc)``: an error naming InvalidAuthToken). Ray's own
    check of the token comes first (``ray.init``'s: where token mode has no token, the GcsClient would end
    the process from C++). Nothing is checked for a stand-in ``ray``, a Ray Client address (``ray://``), or a
    Ray without these calls."""
    if "://" in address or address.lower() in ("auto", "local") or getattr(ray, "_raylet", None) is None:
        return
    client = getattr(ray._raylet, "GcsClient", None)
    try:
        setup = importlib.import_module("ray._private.authentication.authentication_token_setup")
    except ImportError:  # a Ray without token authentication
        return
    ensure = getattr(setup, "ensure_token_if_auth_enabled", None)
    if client is None or ensure is None:
        return
    ensure(None, create_token_if_missing=False)  # raises as ray.init raises: no token in token mode
    try:
        client(address=address)
    except Exception as exc:
        if refused(exc):
            raise ConnectionError(f"Failed to connect to Ray cluster at {address}") from exc
        # another failure (a head still starting): ray.init tries as it did
