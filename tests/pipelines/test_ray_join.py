"""Joining a Ray cluster (pipelines.experiments.ray_join), without Ray installed: a stand-in ``ray`` module
records the calls. What the real Ray 2.60 does at each of these was met by hand (the docstrings say what)."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
import types

import pytest

from pipelines.errors import PipelineError
from pipelines.experiments import ray_join
from pipelines.experiments.ray_join import join_cluster, workers_that_fit


def _answering(first: bytes):
    """A host:port whose server sends ``first`` to each connection, as a gRPC server sends its SETTINGS."""
    server = socket.create_server(("127.0.0.1", 0))

    def serve():
        while True:
            try:
                connection, _ = server.accept()
            except OSError:  # closed: the test is over
                return
            with connection, contextlib.suppress(OSError):
                connection.sendall(first)
                connection.recv(64)  # the client's preface, then its close

    threading.Thread(target=serve, daemon=True).start()
    return server


@pytest.fixture
def listening():
    """A host:port that takes connections and answers as a cluster's head does: Ray 2.60's GCS and Ray
    Client sent these bytes, an HTTP/2 SETTINGS frame, at once (measured at `ray start --head`)."""
    with _answering(b"\0\0\x18\x04\0\0\0\0\0" + b"\0\x04\0@\0\0" * 4) as server:
        yield f"127.0.0.1:{server.getsockname()[1]}"


def _closed_port() -> int:
    with socket.create_server(("127.0.0.1", 0)) as server:
        return server.getsockname()[1]


def _ray(init=None, cpus: float = 8.0) -> types.ModuleType:
    fake = types.ModuleType("ray")
    fake.calls = []  # type: ignore[attr-defined]
    fake.init = init or (lambda **kwargs: fake.calls.append(kwargs))  # type: ignore[attr-defined]
    fake.available_resources = lambda: {"CPU": cpus, "memory": 1e9}  # type: ignore[attr-defined]
    return fake


def test_an_address_where_nothing_listens_is_refused_at_once_without_ray():
    """Ray 2.60's client retried 127.0.0.1:6390 (nothing there) without end, printing "Failed to connect to
    GCS ... within 5 seconds" now and then; Ctrl-C then called it a sweep to resume."""
    port = _closed_port()
    fake = _ray()
    start = time.perf_counter()
    with pytest.raises(PipelineError) as refused:
        join_cluster(fake, f"127.0.0.1:{port}", {})
    assert time.perf_counter() - start < 5 and fake.calls == []  # type: ignore[attr-defined]
    said = str(refused.value)
    assert said.startswith(f"cannot join a Ray cluster at --ray-address '127.0.0.1:{port}': nothing answers")
    assert "Connection refused" in said and "ray status" in said and "\n" not in said
    with pytest.raises(PipelineError, match=f"nothing answers at 127.0.0.1:{port}"):
        join_cluster(fake, f"ray://127.0.0.1:{port}", {})  # Ray Client's port alike


def test_auto_and_an_address_without_a_port_are_left_to_ray(monkeypatch):
    def no_probe(*_args, **_kwargs):
        raise AssertionError("probed")

    monkeypatch.setattr(socket, "create_connection", no_probe)
    fake = _ray()
    for address in ("auto", "head", "head:port"):
        join_cluster(fake, address, {})
    assert [c["address"] for c in fake.calls] == ["auto", "head", "head:port"]  # type: ignore[attr-defined]


def test_a_dashboard_url_is_refused_in_one_line(listening):
    """Ray's refusal of http://head:8265 was a paragraph about RAY_ADDRESS, which the user had not set."""
    fake = _ray()
    with pytest.raises(PipelineError, match=r"is a URL of Ray's dashboard .*host:6379.*ray://host:10001"):
        join_cluster(fake, f"http://{listening}", {})
    assert fake.calls == []  # type: ignore[attr-defined]


def test_a_refused_join_hints_at_token_authentication_unless_it_is_set(listening, monkeypatch):
    """A cluster started with RAY_AUTH_MODE=token refused a driver without it by Ray 2.60's
    ConnectionError("Failed to connect to Ray cluster at ..."), which names no authentication."""

    def init(**_):
        raise ConnectionError("Failed to connect to Ray cluster at 192.0.2.2:6391")

    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    with pytest.raises(PipelineError) as refused:
        join_cluster(_ray(init), listening, {})
    said = str(refused.value)
    assert f"--ray-address '{listening}' (Failed to connect to Ray cluster at 192.0.2.2:6391)" in said
    assert "set RAY_AUTH_MODE=token" in said and said.endswith("for a local Ray")
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    with pytest.raises(PipelineError) as refused:
        join_cluster(_ray(init), listening, {})
    assert "RAY_AUTH_MODE" not in str(refused.value)


def test_rays_own_errors_at_a_join_are_one_line(listening):
    """With RAY_AUTH_MODE=token and no token, Ray 2.60 raised ray.exceptions.AuthenticationError (a RayError,
    no ConnectionError) in a traceback."""

    class RayError(Exception):
        pass

    class AuthenticationError(RayError):
        pass

    def init(**_):
        raise AuthenticationError("Token authentication is enabled but no authentication token was found")

    fake = _ray(init)
    fake.exceptions = types.SimpleNamespace(RayError=RayError)  # type: ignore[attr-defined]
    with pytest.raises(PipelineError, match=r"\(Token authentication is enabled but no .* was found\); give"):
        join_cluster(fake, listening, {})


def test_a_slow_join_says_so(listening, monkeypatch, capsys):
    monkeypatch.setattr(ray_join, "JOIN_NOTE_S", 0.05)
    join_cluster(_ray(lambda **_: time.sleep(0.5)), listening, {})
    err = capsys.readouterr().err
    assert f"note: still joining the Ray cluster at '{listening}' after 0.05 s" in err
    assert "Ctrl-C stops, and nothing has run" in err
    # a quick join, well inside the time even on a loaded host: its timer is cancelled, no word after it
    monkeypatch.setattr(ray_join, "JOIN_NOTE_S", 1.0)
    join_cluster(_ray(), listening, {})
    time.sleep(1.5)
    assert capsys.readouterr().err == ""


def test_a_cluster_with_fewer_free_cpus_than_workers_runs_as_many_as_fit(capsys):
    """Each actor holds a CPU to the end: on a 2-CPU cluster the third of --workers 3 was never placed, and
    the sweep hung in its code check without a word (met with Ray 2.60 on a `ray start --num-cpus 2`)."""
    assert workers_that_fit(_ray(cpus=2.0), "head:6379", 3) == 2
    assert capsys.readouterr().err == (
        "note: the Ray cluster at 'head:6379' has 2 CPUs free for --workers 3: the sweep runs 2 workers (an "
        "autoscaling cluster adds nodes only for work that waits: start its nodes before the sweep)\n"
    )
    assert workers_that_fit(_ray(cpus=3.0), "head:6379", 3) == 3
    assert capsys.readouterr().err == ""
    # a fraction left by another job's tasks places no actor: one, which waits for that job
    assert workers_that_fit(_ray(cpus=0.5), "head:6379", 2) == 1
    assert "has 0 CPUs free for --workers 2: the sweep runs 1 worker; that one waits for a CPU" in (
        capsys.readouterr().err
    )


def _backend_ray(monkeypatch) -> types.ModuleType:
    """A stand-in ``ray`` for pipelines.experiments.backends' RayBackend: not started, recording ``init``'s
    keywords, its actors running the driver's code."""
    import sys

    from pipelines.plugins import code_with_plugins

    fake = _ray()
    fake.is_initialized = lambda: False  # type: ignore[attr-defined]
    actor = types.SimpleNamespace(code=types.SimpleNamespace(remote=lambda: "ref"))
    fake.remote = lambda **_: lambda cls: types.SimpleNamespace(remote=lambda *a: actor)  # type: ignore[attr-defined]
    fake.get = lambda ref: ("node", code_with_plugins())  # type: ignore[attr-defined]
    fake.exceptions = types.SimpleNamespace(RayActorError=RuntimeError)  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", fake)
    return fake


def test_a_sweep_under_ray_address_joins_that_cluster_as_ray_init_does(listening, monkeypatch, capsys):
    """`ray job submit` runs its entrypoint under $RAY_ADDRESS, and a Ray user exports it to have every driver
    join that cluster (ray.init with no address reads it): a sweep without --ray-address started a Ray of its
    own beside the cluster instead ("Started a local Ray instance"), without a word. It joins now, saying so;
    RAY_ADDRESS=local, or a dashboard's URL (Ray Jobs' CLI reads that one), keeps the sweep's own Ray."""
    from pipelines.experiments.backends import RayBackend

    fake = _backend_ray(monkeypatch)
    monkeypatch.setenv("RAY_ADDRESS", listening)
    RayBackend(2, "none", address=None)
    assert [call["address"] for call in fake.calls] == [listening]  # type: ignore[attr-defined]
    assert f"joining the Ray cluster at RAY_ADDRESS='{listening}'" in capsys.readouterr().err
    port = _closed_port()
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{port}")
    with pytest.raises(PipelineError) as refused:
        RayBackend(2, "none", address=None)
    assert str(refused.value).startswith(
        f"cannot join a Ray cluster at RAY_ADDRESS '127.0.0.1:{port}': nothing"
    )
    assert str(refused.value).endswith("or set RAY_ADDRESS=local for a local Ray")
    for own in ("local", "", "http://127.0.0.1:8265"):
        fake.calls.clear()  # type: ignore[attr-defined]
        monkeypatch.setenv("RAY_ADDRESS", own)
        RayBackend(2, "none", address=None)
        assert [call["address"] for call in fake.calls] == ["local"]  # type: ignore[attr-defined]
    # --ray-address is the one joined, beside the variable
    fake.calls.clear()  # type: ignore[attr-defined]
    RayBackend(2, "none", address=listening)
    assert [call["address"] for call in fake.calls] == [listening]  # type: ignore[attr-defined]


def test_ray_address_lets_a_sweep_take_more_workers_than_this_machine(monkeypatch):
    """--workers beyond this machine's cores is refused for a local pool, not for a cluster: $RAY_ADDRESS
    names one as --ray-address does (for Ray's backend; a process pool does not read it)."""
    from pipelines.config.settings import SweepSettings, local_workers_limit

    many = local_workers_limit() + 1
    monkeypatch.setenv("RAY_ADDRESS", "head:6379")
    assert SweepSettings(workers=many, backend="ray").beyond_this_machine() is None
    assert SweepSettings(workers=many, backend="process").beyond_this_machine() is not None
    monkeypatch.setenv("RAY_ADDRESS", "local")
    assert SweepSettings(workers=many, backend="ray").beyond_this_machine() is not None


@pytest.mark.parametrize("mode", [None, "token"])
def test_a_join_refused_for_its_token_says_so_for_sure(listening, monkeypatch, mode):
    """Ray 2.60 refused a driver without the cluster's token, or with a wrong one, by ConnectionError("Failed
    to connect to Ray cluster at ...") raised from a RuntimeError whose text names InvalidAuthToken (met with
    the real Ray: `RAY_AUTH_MODE=token RAY_AUTH_TOKEN=<wrong> crowdmpc sweep --ray-address HOST:6391 ...`
    said only "Failed to connect", nothing about the token). The hint now says which it is."""

    def init(**_):
        try:
            raise RuntimeError(
                "Failed to connect to GCS. Last connection error: ... RPC error: InvalidAuthToken: "
                "Authentication token is missing or incorrect."
            )
        except RuntimeError as cause:
            raise ConnectionError("Failed to connect to Ray cluster at 192.0.2.2:6391") from cause

    if mode is None:
        monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    else:
        monkeypatch.setenv("RAY_AUTH_MODE", mode)
    with pytest.raises(PipelineError) as refused:
        join_cluster(_ray(init), listening, {})
    said = str(refused.value)
    assert "\n" not in said and "(Failed to connect to Ray cluster at 192.0.2.2:6391)" in said
    assert "give the address" not in said  # the address is right
    if mode is None:
        assert (
            "; the cluster wants an authentication token (InvalidAuthToken): set RAY_AUTH_MODE=token" in said
        )
    else:
        assert "; the cluster refused this driver's authentication token (InvalidAuthToken): give " in said


def test_a_sweeps_cpu_projection_is_for_the_workers_the_cluster_fits(
    listening, monkeypatch, capsys, tmp_path
):
    """--workers 4 on a cluster with 2 free CPUs runs 2 actors (workers_that_fit), and the report's last line
    still projected "for 4 workers on 4 free cores": half the wall time the sweep takes. The episodes run
    inline here, behind the stand-in's RayBackend."""
    import re

    from pipelines.cli import main

    _inline_ray_of_two_cpus(monkeypatch, lambda inline, tasks: inline.run(tasks))
    assert main(_ray_sweep(listening, tmp_path, episodes=1)) == 0
    err = capsys.readouterr().err
    assert "has 2 CPUs free for --workers 4: the sweep runs 2 workers" in err
    assert re.search(
        r"the 2 planned episodes take (\d+\.\d) s of CPU: .* s for 2 workers on 2 free cores\n", err
    )


def test_a_stopped_sweeps_cpu_projection_is_for_the_workers_the_cluster_fits(
    listening, monkeypatch, capsys, tmp_path
):
    """A sweep on a cluster that fit 1 of --workers 2 and stopped answering (`ray start --head --num-cpus 1`,
    then `ray stop` once the first records were in): its report projected "for 2 workers on 2 free cores",
    as a stopped sweep's report took the workers asked. The stop carries the workers that ran. Stand-in Ray
    here: one episode inline, then the stop as the backend raises it."""
    from pipelines.cli import main
    from pipelines.errors import SweepStopped
    from pipelines.experiments.ray_join import stopped_answering

    def run_then_lost(inline, tasks):
        yield next(inline.run(tasks))
        raise SweepStopped(stopped_answering(False, "127.0.0.1", 6391, 20.0))

    _inline_ray_of_two_cpus(monkeypatch, run_then_lost)
    assert main(_ray_sweep(listening, tmp_path, episodes=2)) == 2
    err = capsys.readouterr().err
    assert "the 4 planned episodes take" in err and "s for 2 workers on 2 free cores\n" in err
    assert err.strip().splitlines()[-1].startswith("crowdmpc sweep: error: the Ray cluster stopped answering")


def _inline_ray_of_two_cpus(monkeypatch, run) -> None:
    """The stand-in Ray with a cluster of 2 free CPUs, whose RayBackend runs its episodes inline:
    ``run(inline, tasks)`` yields them from an InlineBackend."""
    from pipelines.experiments import backends

    fake = _backend_ray(monkeypatch)
    fake.available_resources = lambda: {"CPU": 2.0}  # type: ignore[attr-defined]
    monkeypatch.setattr(backends, "ray_available", lambda: True)
    inline = backends.InlineBackend("none")
    monkeypatch.setattr(backends.RayBackend, "run", lambda self, tasks: run(inline, tasks))
    monkeypatch.setattr(backends.RayBackend, "close", lambda self: inline.close())


def _ray_sweep(listening: str, tmp_path, episodes: int) -> list[str]:
    """A baselines sweep at 2 humans, ``episodes`` a cell, --workers 4 on the cluster at ``listening``."""
    sweep = ["sweep", "--experiment", "baselines", "--humans", "2", "--episodes-per-cell", str(episodes)]
    ray = ["--backend", "ray", "--ray-address", listening, "--workers", "4"]
    return [*sweep, "--jit", "off", *ray, "--no-progress", "--out", str(tmp_path / "sw")]


@pytest.mark.parametrize("port", ["65536", "99999", "1" + "0" * 30])
def test_a_port_past_65535_is_refused_at_once_without_ray(port):
    """Python's urlsplit refuses such a port (ValueError) and the probe left it to Ray, whose 2.60 client
    retried `127.0.0.1:99999` for ever (as 192.0.2.2:99999, "Failed to connect to GCS ... within 5 seconds",
    still joining after 2 min), where a port that is no number (127.0.0.1:abc) Ray refuses at once."""
    fake = _ray()
    for address, given in ((f"127.0.0.1:{port}", "--ray-address"), (f"ray://head:{port}", "RAY_ADDRESS")):
        with pytest.raises(PipelineError) as refused:
            join_cluster(fake, address, {}, given)
        assert str(refused.value) == (
            f"cannot join a Ray cluster at {given} {address!r}: port {port} is no TCP port (1 to 65535); "
            + ray_join._give_address(given)
        )
    assert fake.calls == []  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    "first", [b"HTTP/1.0 400 Bad Request\r\n\r\n", b"SSH-2.0-OpenSSH_9.6\r\n"], ids=["http", "ssh"]
)
def test_a_port_that_answers_as_another_program_is_refused_at_once_without_ray(first):
    """Ray 2.60 joining 127.0.0.1:PORT of a `python -m http.server` (or a port sending an SSH banner)
    retried it for ever ("Failed to connect to GCS ... within 5 seconds", still joining after 2 min): the
    probe took its connection for a head's. A head's GCS and Ray Client answer an HTTP/2 preface with a
    SETTINGS frame (both measured at `ray start --head`); these servers answer otherwise."""
    fake = _ray()
    with _answering(first) as server:
        address = f"127.0.0.1:{server.getsockname()[1]}"
        start = time.perf_counter()
        with pytest.raises(PipelineError) as refused:
            join_cluster(fake, address, {})
    assert time.perf_counter() - start < 2 and fake.calls == []  # type: ignore[attr-defined]
    assert str(refused.value) == (
        f"cannot join a Ray cluster at --ray-address {address!r}: {address} answers, but not as Ray does "
        f"(its first bytes {first[:16]!r}; a head's GCS and Ray Client speak gRPC): another program's port? "
        + ray_join._give_address("--ray-address")
    )


def test_a_silent_port_or_one_under_tls_is_left_to_ray(monkeypatch):
    """A server that says nothing (a head slow to answer), or any answer where RAY_USE_TLS is on (the
    preface is no TLS hello), is no proof of another program: Ray judges, as before."""
    monkeypatch.setattr(ray_join, "JOIN_ANSWER_S", 0.2)
    fake = _ray()
    with socket.create_server(("127.0.0.1", 0)) as silent:
        join_cluster(fake, f"127.0.0.1:{silent.getsockname()[1]}", {})
    monkeypatch.setenv("RAY_USE_TLS", "1")
    with _answering(b"HTTP/1.0 400 Bad Request\r\n\r\n") as server:
        join_cluster(fake, f"127.0.0.1:{server.getsockname()[1]}", {})
    assert len(fake.calls) == 2  # type: ignore[attr-defined]


def test_rays_warnings_alike_at_a_refused_join_are_said_once(listening, capfd):
    """A cluster refusing the driver's token: Ray 2.60's client wrote "[time W pid tid] gcs_client.cc:210:
    Failed to get cluster ID from GCS server: Unauthenticated: ..." to file descriptor 2 once a second, twenty
    lines alike before the sweep's own line (`RAY_AUTH_MODE=token RAY_AUTH_TOKEN=<wrong> crowdmpc sweep
    --ray-address HOST:6391 ...` on a `ray start --head`). Each distinct line is kept, in order."""
    import os

    refusal = (
        "gcs_client.cc:210: Failed to get cluster ID from GCS server: Unauthenticated: InvalidAuthToken\n"
    )

    def init(**_):
        os.write(2, b"INFO worker.py:1841 -- Connecting to existing Ray cluster\n")
        for second in range(3):
            os.write(2, f"[2026-12-07 23:38:5{second},263 W 28117 28117] {refusal}".encode())
        os.write(2, b"[2026-12-07 23:38:59,001 W 28117 28117] other.cc:1: something else\n")
        raise ConnectionError("Failed to connect to Ray cluster at 192.0.2.2:6391") from RuntimeError(
            "InvalidAuthToken"
        )

    with pytest.raises(PipelineError, match="refused this driver's authentication token|wants an auth"):
        join_cluster(_ray(init), listening, {})
    os.write(2, f"[2026-12-07 23:39:00,000 W 28117 28117] {refusal}".encode())  # after the join: as it comes
    assert capfd.readouterr().err.splitlines() == [
        "INFO worker.py:1841 -- Connecting to existing Ray cluster",
        f"[2026-12-07 23:38:50,263 W 28117 28117] {refusal.strip()}",
        "[2026-12-07 23:38:59,001 W 28117 28117] other.cc:1: something else",
        f"[2026-12-07 23:39:00,000 W 28117 28117] {refusal.strip()}",
    ]


def test_a_ray_job_given_crowdmpc_variables_in_its_runtime_env_still_joins(monkeypatch):
    """`ray job submit --runtime-env-json '{"env_vars": {"CROWDMPC_DATA": ...}}' -- crowdmpc sweep ...`: the
    entrypoint has the job's variables and its job config (RAY_JOB_CONFIG_JSON_ENV_VAR); Ray 2.60's ray.init
    refused to merge the job's runtime_env with the sweep's, which named CROWDMPC_DATA too ("Failed to merge
    the Job's runtime env ... because of a conflict"; met by running the sweep under that variable on a `ray
    start --head`, the head having no Jobs API). The job's own variables are left to the job."""
    import json

    from pipelines.experiments.backends import RayBackend

    fake = _backend_ray(monkeypatch)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setenv("CROWDMPC_DATA", "/data/shared")
    job = {
        "runtime_env": {"working_dir": "gcs://_ray_pkg_x.zip", "env_vars": {"CROWDMPC_DATA": "/data/shared"}}
    }
    monkeypatch.setenv("RAY_JOB_CONFIG_JSON_ENV_VAR", json.dumps(job))
    RayBackend(1, "none", address=None)
    sent = fake.calls[0]["runtime_env"]["env_vars"]  # type: ignore[attr-defined]
    assert "CROWDMPC_DATA" not in sent and sent["OMP_NUM_THREADS"] == "1"
    job["runtime_env"]["env_vars"] = {"OMP_NUM_THREADS": "4"}  # the workers need one thread each
    monkeypatch.setenv("RAY_JOB_CONFIG_JSON_ENV_VAR", json.dumps(job))
    with pytest.raises(
        PipelineError, match=r"sets OMP_NUM_THREADS='4' \(the sweep's: '1'\), and Ray refuses"
    ):
        RayBackend(1, "none", address=None)


@pytest.mark.parametrize("address", ["x..y:6379", "a" * 64 + ":6379", "ray://" + "b" * 64 + ":10001"])
def test_an_address_whose_host_is_no_host_name_is_refused_in_one_line(address):
    """`sweep --backend ray --ray-address x..y:6379` (a typo), or a host label past 63 characters, ended in
    "UnicodeError: encoding with 'idna' codec failed (UnicodeError: label empty or too long)", a traceback:
    the probe caught OSError alone."""
    fake = _ray()
    with pytest.raises(PipelineError) as refused:
        join_cluster(fake, address, {})
    said = str(refused.value)
    assert said.startswith(f"cannot join a Ray cluster at --ray-address {address!r}: ")
    assert "is no host name" in said and "ray start --head" in said and "\n" not in said
    assert fake.calls == []  # type: ignore[attr-defined]
