"""Joining a Ray cluster (``sweep --ray-address``, or ``$RAY_ADDRESS`` as ``ray.init`` reads it): what goes
wrong there is the user's set-up, not a bug, so each failure is one line naming the address (nothing
listening at it, another program's port, a dashboard's URL, a cluster that wants an authentication token,
at once where it refuses the driver's: pipelines.experiments.ray_token, Ray's own refusals), a join that
takes long says so, and on a cluster with fewer free CPUs than workers the sweep runs as many workers as
fit. Ray's C++ warnings that repeat while it retries a refusal show once
(pipelines.experiments.ray_stderr), the variables a `ray job submit` job's runtime_env sets are left to it
(``left_to_the_job``), and a relative --out there, a folder in Ray's copy of the working directory, is
refused (``check_output_outside_job_copy``). It also finds and tries the port whose answer says the cluster
is still there (``gcs_endpoint``, ``answers``). pipelines.experiments.backends' RayBackend calls it."""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path
from typing import Any, Final

from pipelines.errors import PipelineError, print_note
from pipelines.experiments.ray_stderr import repeats_said_once
from pipelines.experiments.ray_token import check_token
from predictors.errors import short_repr

JOIN_PROBE_S: Final[float] = 10.0  # a cluster's head answers a connection at once; a firewall drops it
JOIN_NOTE_S: Final[float] = 30.0
# a gRPC server's SETTINGS frame comes at once; a silent one is Ray's to judge
JOIN_ANSWER_S: Final[float] = 3.0
HTTP2_PREFACE: Final[bytes] = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"  # what an HTTP/2 client sends first
GRPC_SETTINGS: Final[bytes] = b"\0\0\0\x04\0\0\0\0\0"  # an empty SETTINGS frame: 9 bytes, type 4, stream 0
RAY_ADDRESS_ENV: Final[str] = "RAY_ADDRESS"  # what ray.init joins when given no address (Ray's docs)
# Ray's job supervisor's: a `ray job submit` entrypoint's job config, its runtime_env among it (Ray 2.60)
RAY_JOB_CONFIG_ENV: Final[str] = "RAY_JOB_CONFIG_JSON_ENV_VAR"


def address_from_environment() -> str | None:
    """``$RAY_ADDRESS`` where it names a cluster: a `ray job submit` entrypoint runs under it, and a Ray user
    sets it to have every driver join that cluster; a sweep that ignored it started a Ray of its own beside
    the cluster, without a word. None when unset, empty or ``local`` (Ray's word for a Ray of one's own),
    and for a dashboard's URL: Ray's Jobs docs have it exported for `ray job submit` (no driver joins it),
    and a sweep beside that export ran on a Ray of its own before it read the variable."""
    address = os.environ.get(RAY_ADDRESS_ENV, "").strip()
    dashboard = address.lower().startswith(("http://", "https://"))
    return None if not address or address.lower() == "local" or dashboard else address


def joining_from_environment(address: str) -> None:
    print_note(
        f"note: joining the Ray cluster at {RAY_ADDRESS_ENV}={address!r}, as ray.init does; set "
        f"{RAY_ADDRESS_ENV}=local (or unset it) for a Ray of this machine's own"
    )


def stopped_answering(local: bool, host: str, port: int, silent_s: float) -> str:
    """Why a sweep stopped when its Ray's GCS went silent. A sweep's own local Ray (no --ray-address, no
    $RAY_ADDRESS) has no cluster to come back: a rerun starts a new one, so it is not told to wait."""
    if local:
        return (
            f"this sweep's own local Ray stopped answering (its GCS at {host}:{port}, for {silent_s:g} s: "
            "`ray stop` on this machine, or its processes killed); the episodes recorded stay, and the same "
            "command runs the rest on a new local Ray"
        )
    return (
        f"the Ray cluster stopped answering (its GCS at {host}:{port}, for {silent_s:g} s: "
        "`ray stop`, or its head lost); the episodes recorded stay, and the same command "
        "runs the rest once the cluster is back"
    )


def gcs_endpoint(ray: Any, address: str | None) -> tuple[str, int] | None:
    """The (host, port) whose answer says the cluster is there: Ray Client's server for a ray:// address
    (the driver reaches no other port of the cluster), else the GCS the driver is connected to; None where
    Ray does not say (a stand-in ray, another Ray version)."""
    from urllib.parse import urlsplit

    try:
        if address is not None and address.lower().startswith("ray://"):
            parts = urlsplit(address)
            host, port = parts.hostname, parts.port
        else:
            host, _, number = str(ray.get_runtime_context().gcs_address).rpartition(":")
            port = int(number)
    except (AttributeError, ValueError, TypeError):
        return None
    return (host, port) if host and port else None


def answers(endpoint: tuple[str, int], timeout_s: float) -> bool:
    """Whether ``endpoint`` takes a TCP connection within ``timeout_s``: the cluster's GCS is there."""
    import socket

    try:
        socket.create_connection(endpoint, timeout=timeout_s).close()
    except OSError:
        return False
    return True


def join_cluster(ray: Any, address: str, env: dict[str, Any], given: str = "--ray-address") -> None:
    """``ray.init`` on a cluster's address; its failures (no cluster there, an address Ray cannot parse) are
    one line naming the address: they are the user's input, not a bug. Ray's client retries a silent port
    for ever, so a host:port is tried first (``_check_answers``), and a join still going after
    ``JOIN_NOTE_S`` says so rather than wait without a word. ``given``: where the address came from, as the
    messages name it (the option, or ``RAY_ADDRESS``)."""
    _check_address_kind(address, given)
    _check_answers(address, given)
    waiting = threading.Timer(JOIN_NOTE_S, _still_joining, (address,))
    waiting.daemon = True
    waiting.start()
    # Ray's own errors at a join are the set-up's: a missing authentication token (AuthenticationError)
    refused: tuple[type[BaseException], ...] = (ConnectionError, ValueError, RuntimeError)
    ray_error = getattr(getattr(ray, "exceptions", None), "RayError", None)
    if isinstance(ray_error, type) and issubclass(ray_error, BaseException):
        refused += (ray_error,)
    try:
        with repeats_said_once():  # Ray's C++ client warns once a second while it retries a refusal
            check_token(ray, address, _refused_token)  # a refused token at once, not after 20 s of tries
            ray.init(address=address, runtime_env=env, log_to_driver=False)
    except refused as exc:
        # refused for its token: the address is right, and the hint is the whole answer
        tail = "" if _refused_token(exc) else f"; {_give_address(given)}"
        raise PipelineError(
            f"cannot join a Ray cluster at {given} {address!r} ({_first_line(exc)}){_auth_hint(exc)}{tail}"
        ) from None
    finally:
        waiting.cancel()


def left_to_the_job(env_vars: dict[str, str]) -> dict[str, str]:
    """``env_vars`` for the actors, less those a `ray job submit` job's runtime_env sets to the same value:
    the entrypoint's ray.init merges the job's runtime_env with the driver's and refuses a variable both name,
    even alike (Ray 2.60: "Failed to merge the Job's runtime env ... because of a conflict"), so a job given
    CROWDMPC_DATA in its --runtime-env-json never joined. The job's own variables reach every actor. One the
    job sets to another value than the sweep's workers need is refused in one line, naming it."""
    job = _job_runtime_env()
    try:
        job_vars = {str(k): str(v) for k, v in (job.get("env_vars") or {}).items()} if job else {}
    except AttributeError:  # not a job config this code knows: Ray's to read, as it does
        return env_vars
    differ = [  # cut: a job's value may be any length, and the line names it beside the sweep's
        f"{k}={short_repr(job_vars[k])} (the sweep's: {short_repr(v)})"
        for k, v in env_vars.items()
        if job_vars.get(k, v) != v
    ]
    if differ:
        raise PipelineError(
            f"the Ray job's runtime_env sets {', '.join(differ)}, and Ray refuses a variable that the job "
            "and the sweep's workers both set: leave it out of the job's env_vars (the driver's CROWDMPC_* "
            "variables reach the workers without it)"
        )
    return {k: v for k, v in env_vars.items() if k not in job_vars}


def job_working_copy() -> Path | None:
    """The folder this process runs in where it is a `ray job submit --working-dir` entrypoint there: Ray
    2.60 unpacks the uploaded folder into its cache on the head, runs the entrypoint in it and puts it first
    on PYTHONPATH. None for no job, a job without a working_dir (it runs where `ray start` was run), or an
    entrypoint that went elsewhere (`bash -c "cd /x && ..."`)."""
    job = _job_runtime_env()
    if not job or not job.get("working_dir"):
        return None
    here = os.path.realpath(os.getcwd())
    entries = os.environ.get("PYTHONPATH", "").split(os.pathsep)
    return Path(here) if any(e and os.path.realpath(e) == here for e in entries) else None


def check_output_outside_job_copy(out: Path, label: str) -> None:
    """PipelineError for a relative ``out`` in a `ray job submit --working-dir` entrypoint: it named a folder
    in Ray's copy of the working directory, which the submitting machine never sees and Ray's working_dir
    cache may delete once the job ends, while the sweep said "wrote rel/table.md" as if it were beside the
    user's files (met with Ray 2.60: `ray job submit --working-dir . -- crowdmpc sweep ... --out rel`)."""
    copy = job_working_copy()
    if copy is None or out.is_absolute():
        return
    raise PipelineError(
        f"{label} {str(out)!r} is a relative path, and this sweep runs as a `ray job submit --working-dir` "
        f"entrypoint in Ray's copy of that folder on the head ({copy}), which Ray's cache may delete once "
        "the job ends: give an absolute path on the head"
    )


def _job_runtime_env() -> dict[str, Any] | None:
    """The runtime_env of the `ray job submit` job this process is the entrypoint of ({} for none); None
    where its job config is no JSON object this code knows (Ray's to read, as it does)."""
    try:
        job = json.loads(os.environ.get(RAY_JOB_CONFIG_ENV) or "{}").get("runtime_env") or {}
    except (ValueError, AttributeError, RecursionError):  # nested past json's stack: no config of ours
        return None
    return job if isinstance(job, dict) else None


def _give_address(given: str) -> str:
    leave = "set RAY_ADDRESS=local" if given == RAY_ADDRESS_ENV else "leave --ray-address out"
    return f"give the address that `ray start --head` printed, or {leave} for a local Ray"


def _check_address_kind(address: str, given: str) -> None:
    """A dashboard's URL (Ray Jobs' ``http://head:8265``) is no address a driver joins: Ray's refusal of it
    ran to a paragraph."""
    scheme = address.split("://", 1)[0].lower() if "://" in address else None
    if scheme in ("http", "https"):
        raise PipelineError(
            f"{given} {address!r} is a URL of Ray's dashboard (for `ray job submit`), not a cluster a "
            "sweep joins: give the head's address that `ray start --head` printed (host:6379), or "
            "ray://host:10001 through Ray Client"
        )


def _check_answers(address: str, given: str) -> None:
    """PipelineError unless ``address``'s host takes a TCP connection at its port within ``JOIN_PROBE_S``
    (``auto`` and an address without a port are left to Ray): with nothing listening there, ``ray.init``
    retried without end, and a Ctrl-C then read as a sweep to resume; so it did at a port whose server
    answers as no Ray does (``_first_bytes``), also refused."""
    import socket
    from urllib.parse import urlsplit

    if address.lower() in ("auto", "local"):
        return
    try:
        parts = urlsplit(address if "://" in address else f"//{address}")
    except ValueError:  # an unclosed [ of an IPv6 host: Ray's own words name it
        return
    try:
        host, port = parts.hostname, parts.port
    except ValueError:  # a port that is no number: Ray's own words name it
        number = parts.netloc.rpartition(":")[2]
        if number.isdigit():  # past 65535, which Ray's client retried for ever as it does a silent port
            raise PipelineError(
                f"cannot join a Ray cluster at {given} {address!r}: port {number} is no TCP port "
                f"(1 to 65535); {_give_address(given)}"
            ) from None
        return
    if not host or port is None:
        return
    try:
        with socket.create_connection((host, port), timeout=JOIN_PROBE_S) as connection:
            first = _first_bytes(connection)
    except UnicodeError as exc:  # IDNA refuses the host before any lookup: a label empty (x..y) or too long
        raise PipelineError(
            f"cannot join a Ray cluster at {given} {address!r}: {host!r} is no host name ({exc}); "
            f"{_give_address(given)}"
        ) from None
    except OSError as exc:
        reason = f"no answer in {JOIN_PROBE_S:g} s" if isinstance(exc, TimeoutError) else exc.strerror or exc
        raise PipelineError(
            f"cannot join a Ray cluster at {given} {address!r}: nothing answers at {host}:{port} "
            f"({reason}); is the cluster running (`ray status` on its head)? {_give_address(given)}"
        ) from None
    if len(first) >= len(GRPC_SETTINGS) and not _is_grpc(first):
        raise PipelineError(
            f"cannot join a Ray cluster at {given} {address!r}: {host}:{port} answers, but not as Ray does "
            f"(its first bytes {first[:16]!r}; a head's GCS and Ray Client speak gRPC): another program's "
            f"port? {_give_address(given)}"
        )


def _first_bytes(connection: Any) -> bytes:
    """What a server sends first to an HTTP/2 client (gRPC's transport): a gRPC server, a Ray head's GCS or
    Ray Client's (Ray 2.60, both), answers with its SETTINGS frame at once; an HTTP/1 server, an SSH daemon
    or another program with other bytes, and Ray's client then retried them for ever. Bytes read within
    ``JOIN_ANSWER_S`` (none where the server is silent, closes, or TLS is on: then Ray is left to judge)."""
    if os.environ.get("RAY_USE_TLS", "").lower() in ("1", "true"):  # the server awaits a TLS hello
        return b""
    data = b""
    try:
        connection.settimeout(JOIN_ANSWER_S)
        connection.sendall(HTTP2_PREFACE + GRPC_SETTINGS)
        while len(data) < len(GRPC_SETTINGS):
            chunk = connection.recv(64)
            if not chunk:
                break
            data += chunk
    except OSError:  # a timeout (TimeoutError) or a reset: what came so far
        pass
    return data


def _is_grpc(first: bytes) -> bool:
    """Whether ``first`` begins with an HTTP/2 SETTINGS frame on stream 0, as every HTTP/2 server's first
    frame is (RFC 9113, 3.4): a 3-byte length, type 0x4, a flags byte, a 4-byte stream id of 0."""
    return first[3] == 0x04 and first[5:9] == b"\0\0\0\0"


def _still_joining(address: str) -> None:
    print_note(
        f"note: still joining the Ray cluster at {address!r} after {JOIN_NOTE_S:g} s (Ray retries while the "
        "cluster does not answer); Ctrl-C stops, and nothing has run"
    )


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _auth_hint(exc: BaseException) -> str:
    """A cluster started with token authentication refuses a driver without it by a ConnectionError whose
    message names no authentication (Ray 2.60: "Failed to connect to Ray cluster at ..."); the error it was
    raised from does ("InvalidAuthToken"), where Ray says so: then the hint says it for sure, a wrong token
    of a driver in token mode too (which had no hint at all). Where it does not, a hint that it may be so."""
    token = "the cluster's token (~/.ray/auth_token, $RAY_AUTH_TOKEN or $RAY_AUTH_TOKEN_PATH)"
    in_token_mode = os.environ.get("RAY_AUTH_MODE", "").lower() == "token"
    if _refused_token(exc):
        if in_token_mode:
            return (
                f"; the cluster refused this driver's authentication token (InvalidAuthToken): give {token}"
            )
        return (
            "; the cluster wants an authentication token (InvalidAuthToken): set RAY_AUTH_MODE=token where "
            f"the sweep runs, with {token}"
        )
    if isinstance(exc, ConnectionError) and not os.environ.get("RAY_AUTH_MODE"):
        return (
            "; a cluster started with token authentication refuses so too: then set RAY_AUTH_MODE=token "
            "where the sweep runs, with the cluster's token (~/.ray/auth_token or $RAY_AUTH_TOKEN)"
        )
    return ""


def _refused_token(exc: BaseException) -> bool:
    """Whether ``exc`` or an error it was raised from names Ray's refusal of the driver's token."""
    seen: BaseException | None = exc
    for _ in range(8):  # a chain of causes is short; a cycle would loop for ever
        if seen is None:
            return False
        if "InvalidAuthToken" in str(seen):
            return True
        seen = seen.__cause__ or seen.__context__
    return False


def workers_that_fit(ray: Any, address: str, workers: int) -> int:
    """How many of --workers actors to start on the joined cluster: as many as it has free CPUs (each actor
    takes one), at least one, said in a note when fewer than asked. Each actor holds its CPU to the end, so
    one that found none waited for ever (the sweep hung in its code check, without a word); a cluster that
    autoscales adds nodes only while actors wait, so its nodes are best started first (said too)."""
    cpus = int(ray.available_resources().get("CPU", 0))  # what other jobs on the cluster leave
    if workers <= cpus:
        return workers
    fit = max(cpus, 1)
    wait = "; that one waits for a CPU another job frees" if cpus == 0 else ""
    print_note(
        f"note: the Ray cluster at {address!r} has {cpus} CPU{'' if cpus == 1 else 's'} free for --workers "
        f"{workers}: the sweep runs {fit} worker{'' if fit == 1 else 's'}{wait} (an autoscaling cluster "
        "adds nodes only for work that waits: start its nodes before the sweep)"
    )
    return fit
