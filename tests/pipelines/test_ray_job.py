"""A sweep as a `ray job submit` entrypoint, without Ray installed: the job's environment is set as Ray 2.60's
job supervisor set it (met by `ray job submit --working-dir . -- python -c ...` on a `ray start --head`):
RAY_JOB_CONFIG_JSON_ENV_VAR holds the job's runtime_env, and with a working_dir the entrypoint runs in
Ray's unpacked copy of it, first on PYTHONPATH."""

from __future__ import annotations

import json

import pytest

from pipelines.cli import main

SWEEP = ["sweep", "--experiment", "baselines", "--humans", "2", "--episodes-per-cell", "1", "--workers", "1"]


def _job(monkeypatch, copy, working_dir: bool = True, on_pythonpath: bool = True) -> None:
    runtime_env = (
        {"working_dir": "gcs://_ray_pkg_34e2b460ba75db30.zip", "env_vars": {}} if working_dir else {}
    )
    job = {"runtime_env": runtime_env, "metadata": {"job_submission_id": "raysubmit_x"}}
    monkeypatch.setenv("RAY_JOB_CONFIG_JSON_ENV_VAR", json.dumps(job))
    monkeypatch.setenv("PYTHONPATH", str(copy) if on_pythonpath else "")
    monkeypatch.chdir(copy)


def test_a_relative_out_in_a_working_dir_job_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """`ray job submit --working-dir . -- crowdmpc sweep ... --out rel1` ran, said "wrote rel1/table.md",
    and left the sweep in session_*/runtime_resources/working_dir_files/_ray_pkg_*/rel1 on the head."""
    copy = tmp_path / "_ray_pkg_34e2b460ba75db30"
    copy.mkdir()
    _job(monkeypatch, copy)
    assert main([*SWEEP, "--out", "rel1", "--backend", "inline"]) == 2
    said = capsys.readouterr().err.strip()
    assert "\n" not in said and "--out 'rel1' is a relative path" in said
    assert f"Ray's copy of that folder on the head ({copy})" in said and "give an absolute path" in said
    assert not (copy / "rel1").exists()


@pytest.mark.parametrize("where", ["absolute", "job without working_dir", "entrypoint elsewhere", "no job"])
def test_other_outs_of_a_job_are_left_alone(tmp_path, monkeypatch, where):
    """An absolute --out; a job without --working-dir (its entrypoint runs where `ray start` was run, a
    folder that stays); an entrypoint that changed folder; no job at all: the --dry-run plans as ever."""
    from pipelines.experiments.ray_join import check_output_outside_job_copy, job_working_copy

    copy = tmp_path / "copy"
    copy.mkdir()
    _job(
        monkeypatch,
        copy,
        working_dir=where != "job without working_dir",
        on_pythonpath=where != "entrypoint elsewhere",
    )
    if where == "no job":
        monkeypatch.delenv("RAY_JOB_CONFIG_JSON_ENV_VAR")
    out = str(tmp_path / "runs" / "s1") if where == "absolute" else "s1"
    assert main([*SWEEP, "--out", out, "--dry-run", "--no-progress"]) == 0
    assert job_working_copy() == (copy if where == "absolute" else None)
    check_output_outside_job_copy(tmp_path / "s1", "--out")  # absolute: never refused


def test_the_cluster_extra_brings_the_jobs_api_and_ray_client():
    """The [cluster] extra was plain ray: a head installed from it refused `ray job submit` ("Failed to
    connect to Ray at address: http://127.0.0.1:8266"; its dashboard serves the Jobs API), its own `ray job
    submit` wanted ray[default], and `sweep --ray-address ray://HOST:10001`, which `sweep --help` offers,
    met "Ray Client requires pip package `ray[client]`" (Ray 2.60). ray[default] brings both (grpcio)."""
    import tomllib
    from pathlib import Path

    from packaging.requirements import Requirement

    pyproject = Path(__file__).parents[2] / "pyproject.toml"
    extras = tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    extra = extras["cluster"]
    rays = [Requirement(text) for text in extra if Requirement(text).name == "ray"]
    assert len(rays) == 1 and "default" in rays[0].extras


def test_a_job_config_nested_past_the_stack_is_left_to_ray(tmp_path, monkeypatch, capsys):
    """RAY_JOB_CONFIG_JSON_ENV_VAR holding 100,000 "[" ended every sweep in "RecursionError: maximum
    recursion depth exceeded while decoding a JSON array" (check_output_outside_job_copy reads it before any
    sweep runs): a config this code cannot read is Ray's to read, as one that is no JSON object."""
    from pipelines.experiments.ray_join import left_to_the_job

    monkeypatch.setenv("RAY_JOB_CONFIG_JSON_ENV_VAR", "[" * 100_000)
    assert left_to_the_job({"CROWDMPC_DATA": "/d"}) == {"CROWDMPC_DATA": "/d"}
    assert main([*SWEEP, "--out", str(tmp_path / "s1"), "--dry-run", "--no-progress"]) == 0


def test_a_jobs_long_variable_is_named_cut(monkeypatch):
    """A job whose runtime_env set CROWDMPC_DATA to 100,000 characters other than the sweep's was refused in a
    line of 100,242 characters, the value whole: each value is now cut as other refusals cut one."""
    from pipelines.errors import PipelineError
    from pipelines.experiments.ray_join import left_to_the_job

    job = {"runtime_env": {"env_vars": {"CROWDMPC_DATA": "x" * 100_000}}}
    monkeypatch.setenv("RAY_JOB_CONFIG_JSON_ENV_VAR", json.dumps(job))
    with pytest.raises(PipelineError) as refused:
        left_to_the_job({"CROWDMPC_DATA": "/d"})
    said = str(refused.value)
    assert len(said) < 400 and "CROWDMPC_DATA='xxx" in said and "(the sweep's: '/d')" in said
