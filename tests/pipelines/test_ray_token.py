"""A cluster that refuses the driver's authentication token refuses the sweep at once (ray_token): Ray 2.60's
``ray.init`` tried twenty times, a second apart, before the sweep's line. With the real Ray: a local head in
token mode, and drivers of their own processes (Ray keeps a process's token once read)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

_GOOD = "crowdmpc-test-token-" + "g" * 24
_HEAD = """
import sys, ray
ray.init(address="local", num_cpus=1, include_dashboard=False, log_to_driver=False)
print(ray.get_runtime_context().gcs_address, flush=True)
sys.stdin.read()  # until the test closes it
ray.shutdown()
"""
_JOIN = """
import sys, time, ray
from pipelines.errors import PipelineError
from pipelines.experiments.ray_join import join_cluster
start = time.monotonic()
try:
    join_cluster(ray, sys.argv[1], {})
    print("joined")
    ray.shutdown()
except PipelineError as exc:
    print(exc)
print(f"{time.monotonic() - start:.2f}")
"""


def _environment(tmp_path: Path, **env: str) -> dict[str, str]:
    root = str(Path(__file__).resolve().parents[2])
    keep = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    return keep | {"HOME": str(tmp_path), "PYTHONPATH": root} | env  # no token of this machine's


@pytest.fixture
def token_head(tmp_path):
    """A local Ray head in token mode, its GCS's host:port; it ends when the test does."""
    pytest.importorskip("ray")  # the [cluster] extra
    env = _environment(tmp_path, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=_GOOD)
    head = subprocess.Popen(
        [sys.executable, "-c", _HEAD], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        address = head.stdout.readline().strip()  # type: ignore[union-attr]
        assert address, "the Ray head did not start"
        yield address
    finally:
        head.stdin.close()  # type: ignore[union-attr]
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait()


def _join(tmp_path: Path, address: str, **env: str) -> tuple[str, float]:
    done = subprocess.run(
        [sys.executable, "-c", _JOIN, address],
        env=_environment(tmp_path, **env),
        capture_output=True,
        text=True,
        timeout=120,
    )
    said, took = done.stdout.strip().splitlines()[-2:]
    return said, float(took)


@pytest.mark.parametrize("mode", ["token", None])
def test_a_refused_token_is_refused_at_once_and_a_good_one_joins(token_head, tmp_path, mode):
    """`RAY_AUTH_MODE=token RAY_AUTH_TOKEN=<wrong> crowdmpc sweep --ray-address HOST:PORT ...` (or no token
    mode) waited 20 s for its line; it now comes at once, the same line, and the right token still joins."""
    wrong = {"RAY_AUTH_TOKEN": "crowdmpc-test-token-" + "w" * 24} | ({"RAY_AUTH_MODE": mode} if mode else {})
    said, took = _join(tmp_path, token_head, **wrong)
    assert said.startswith(f"cannot join a Ray cluster at --ray-address {token_head!r} (Failed to connect")
    assert ("refused this driver's authentication token" if mode else "wants an authentication token") in said
    assert took < 5.0  # Ray's tries took 20 s
    said, took = _join(tmp_path, token_head, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=_GOOD)
    assert said == "joined"
