"""What `crowdmpc review` says ended a gymnasium episode: the metrics' timeout is "not success" (Table II's),
so an episode that a contact (end_on_collision) or its own loop ended before the time limit read "timeout
yes" as if the time limit had ended it."""

import json
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from mcap.reader import make_reader

import crowdsim  # noqa: F401  (registers the environment)
from crowdsim.gym_env import POSITION, PRESENT
from crowdsim.gym_wrappers import VelocityControl
from pipelines.cli import main
from pipelines.logs.ending import _last_step_contact
from pipelines.logs.reader import read_recording
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.logs.review import format_summary, summarize
from pipelines.loop.gym_loop import ObserveEpisodes
from tests.pipelines.mcap_files import write_mcap


def _record(
    out, policy, *, end_on_collision=False, step_limit=None, controller="test_policy", seed=1, profile=None
):
    """One episode of ``seed`` with 3 robots among 5 humans who do not see them, recorded; its file."""
    base = gym.make(
        "crowdmpc/CrowdNav-v0",
        config={"visibility": "invisible", **({"profile": profile} if profile else {})},
        n_humans=5,
        end_on_collision=end_on_collision,
    )
    with McapEpisodeRecorder(out) as recorder:
        env = ObserveEpisodes(base, [recorder], controller=controller)
        if step_limit is not None:
            env = gym.wrappers.TimeLimit(env, max_episode_steps=step_limit)
        env = VelocityControl(env)
        obs, info = env.reset(seed=seed)
        rows, n = base.unwrapped.max_robots, info["n_robots"]
        done = False
        while not done:
            velocities = np.zeros((rows, 2))
            velocities[:n] = policy(obs[:n], obs[rows:][obs[rows:, PRESENT] == 1])
            obs, _, terminated, truncated, info = env.step(velocities)
            done = terminated or truncated
        env.close()
    (path,) = recorder.paths
    return path


def _chase(robots, humans):  # every robot heads for the first human
    return np.clip(humans[0, POSITION] - robots[:, POSITION], -1.0, 1.0)


def _stand(robots, humans):
    return np.zeros((len(robots), 2))


@pytest.mark.parametrize(
    ("policy", "options", "ended", "timeout_row"),
    [
        (_chase, {"end_on_collision": True}, "contact", "yes (the metric: not success; the time limit"),
        (_stand, {"step_limit": 5}, "cut_short", "yes (the metric: not success; the time limit"),
        (_stand, {}, "time_limit", "yes\n"),
    ],
)
def test_review_names_what_ended_the_episode(tmp_path, capsys, policy, options, ended, timeout_row):
    path = _record(tmp_path / "runs", policy, **options)
    summary = summarize(read_recording(path))
    assert summary["ended_by"] == ended
    assert summary["metrics"]["timeout"] is True  # the recorded metric, as the sweeps count it
    text = format_summary(summary)
    assert f"  timeout                            {timeout_row}" in text + "\n"
    assert main(["review", str(path), "--json", str(tmp_path / "r.json")]) == 0
    assert json.loads((tmp_path / "r.json").read_text())["summary"]["ended_by"] == ended
    (row,) = [line for line in capsys.readouterr().out.splitlines() if line.startswith("ended ")]
    said = {
        "contact": "robot-human contact at 5.2 s, before the time limit",
        "cut_short": "stopped at 2.0 s by its loop, before the time limit",
        "time_limit": "time limit at 39.2 s",
    }
    assert row.split(None, 1)[1].startswith(said[ended])


def test_a_success_is_said_as_such(tmp_path):
    goal = lambda robots, humans: np.clip(robots[:, 4:6] - robots[:, POSITION], -1.0, 1.0)  # noqa: E731
    summary = summarize(read_recording(_record(tmp_path / "runs", goal)))
    assert summary["ended_by"] == "success" and summary["metrics"]["timeout"] is False
    assert "ended                                success at 10.4 s" in format_summary(summary)


def test_a_folders_table_and_a_comparison_say_what_ended_each_run(tmp_path, capsys):
    """The table over runs and `review --compare` gave the timeout column alone: "yes" for both."""
    # two policies: one policy's two episodes of a seed are copies of one episode, which a folder counts once
    contact = _record(tmp_path / "runs" / "contact", _chase, end_on_collision=True, controller="chase")
    limit = _record(tmp_path / "runs" / "limit", _stand, controller="stand")
    assert main(["review", str(tmp_path / "runs")]) == 0
    rows = {line.split()[0]: line.split() for line in capsys.readouterr().out.splitlines() if ".mcap" in line}
    assert rows["contact/circle_seed000001.mcap"][5:9] == ["yes", "-", "0.368", "contact"]
    assert rows["limit/circle_seed000001.mcap"][5:9] == ["yes", "-", "1.41", "time_limit"]
    assert main(["review", str(contact), "--compare", str(limit)]) == 0
    lines = capsys.readouterr().out.splitlines()
    *_, row = [line for line in lines if line.startswith("ended ")]
    assert row.split()[1:] == ["contact", "time_limit"]  # the comparison's, after A's summary
    # the comparison's timeout row as the summary words it: a bare "yes" read as the time limit's
    *_, row = [line for line in lines if line.startswith("timeout ")]
    assert row.split(None, 1)[1].rstrip().endswith("the time limit did not end it)  yes")


def test_the_folders_totals_count_what_ended_its_episodes(tmp_path, capsys):
    """The totals line said "timeout 100.0 % (2/2)" of a contact and a time limit, the metric (not success),
    with nothing beside it to say that a contact ended one of them."""
    _record(tmp_path / "runs" / "contact", _chase, end_on_collision=True)
    _record(tmp_path / "runs" / "limit", _stand, seed=2)  # one set-up of two episodes: the folder's totals
    assert main(["review", str(tmp_path / "runs"), "--json", str(tmp_path / "r.json")]) == 0
    lines = capsys.readouterr().out.splitlines()
    (rates,) = [i for i, line in enumerate(lines) if line.startswith("success ")]
    assert "timeout 100.0 % (2/2)" in lines[rates]  # the metric as Table II counts it, unchanged
    assert lines[rates + 1].startswith("ended by: success 0, time limit 1, contact 1, cut short 0; ")
    totals = json.loads((tmp_path / "r.json").read_text())["totals"]
    assert totals["timeout_count"] == 2 and totals["success_count"] == 0
    assert totals["ends"] == {"success": 0, "time_limit": 1, "contact": 1, "cut_short": 0, "untold": 0}


def _older(source: Path, out: Path, run: dict[str, str]) -> Path:
    """``source`` as simulate recorded it before the "config" metadata held the env (586091d): format 2, a
    config without env (an MPC's settings alone, none here) and ``run`` as its "run" metadata."""
    with source.open("rb") as f:
        reader = make_reader(f)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = list(reader.iter_messages())
    metadata["crowdmpc"] = {**metadata["crowdmpc"], "format": "crowdmpc-episode/2"}
    metadata["config"], metadata["run"] = {}, {k: json.dumps(v) for k, v in run.items()}
    return _write(out, metadata, messages)


def _write(out: Path, metadata: dict[str, dict[str, str]], messages: list) -> Path:
    """An MCAP file of these metadata records and ``messages``, its header crowdmpc's."""
    return write_mcap(out, metadata, messages, library="crowdmpc")


@pytest.mark.parametrize(
    ("profile", "run", "ended"),
    [
        ("paper", {"command": "simulate", "profile": "paper"}, "time_limit"),  # 6762d28 to 586091d
        ("v1", {"command": "simulate", "profile": "v1"}, "time_limit"),
        ("v1", {"command": "simulate"}, "time_limit"),  # before the profiles: the first simulator's 30 s
        ("paper", {"command": "simulate"}, None),  # 98 steps that simulate then could not have run
        ("paper", {"experiment": "baselines", "cell": "orca"}, None),  # a sweep's cell could set the limit
    ],
)
def test_an_older_simulates_recording_tells_its_time_limit(tmp_path, profile, run, ended):
    """A file recorded before the config held the env (no env.timeout_margin) had ended_by null although
    simulate's "run" metadata named the profile it ran unchanged (or, before the profiles, ran the one
    simulator there was); a file whose run does not tell its limit stays null."""
    path = _record(tmp_path / "runs", _stand, profile=profile)
    older = read_recording(_older(path, tmp_path / "older.mcap", run))
    assert "env" not in older.config() and older.episode()["dt"] == "0.4"
    summary = summarize(older)
    assert summary["metrics"]["timeout"] is True and summary["ended_by"] == ended


@pytest.mark.parametrize(
    "env",
    [
        '{"dt": 0.4, "time_limit": 1' + "0" * 400 + ', "timeout_margin": 1.0}',  # overflowed float()
        '{"dt": true, "time_limit": 40.0, "timeout_margin": 1.0}',
        '{"dt": "0.4", "time_limit": 40.0, "timeout_margin": 1.0}',
    ],
    ids=["huge", "bool", "text"],
)
def test_a_recorded_env_of_no_numbers_leaves_the_end_untold(tmp_path, capsys, env):
    """A config whose env holds an integer float() cannot take ended the review in a traceback, and a bool or
    a text, which no recorder writes, was read as a time step."""
    path = _record(tmp_path / "runs", _stand, step_limit=5)
    with path.open("rb") as f:
        reader = make_reader(f)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = list(reader.iter_messages())
    metadata["config"] = {**metadata["config"], "env": env}
    edited = _write(tmp_path / "edited.mcap", metadata, messages)
    assert summarize(read_recording(edited))["ended_by"] is None
    assert main(["review", str(edited)]) == 0
    assert "ended                                -" in capsys.readouterr().out


@pytest.mark.parametrize("n_steps", [-3, True, 5.0])
def test_metrics_of_no_step_count_are_left_out_and_fail_the_check(tmp_path, capsys, n_steps):
    """The metrics' n_steps, from which the review tells what ended the episode, was taken unchecked: -3 or
    true read as a loop that stopped early, and --check called the file ok."""
    path = _record(tmp_path / "runs", _stand, step_limit=5)
    with path.open("rb") as f:
        reader = make_reader(f)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = list(reader.iter_messages())
    for i, (schema, channel, message) in enumerate(messages):
        if channel.topic == "/episode/metrics":
            record = json.loads(message.data)
            record["metrics"]["n_steps"] = n_steps
            messages[i] = (schema, channel, replace(message, data=json.dumps(record).encode()))
    edited = _write(tmp_path / "edited.mcap", metadata, messages)
    assert summarize(read_recording(edited))["ended_by"] is None
    assert main(["review", str(edited), "--check"]) == 1
    assert f"'metrics' 'n_steps' is {n_steps!r}, expected a count of steps" in capsys.readouterr().out


def test_a_loop_that_stops_on_a_step_that_touched_is_no_contact_end(tmp_path):
    """A TimeLimit around ObserveEpisodes that cut an episode on a step where a robot touched a human read
    "ended: contact" (outputs.md: a contact ends only an episode with end_on_collision), though this
    environment, end_on_collision off, goes on after a contact. A recording older than the recorded
    end_on_collision is still read from its last step, as before."""
    path = _record(tmp_path / "runs", _chase, step_limit=13)  # the step of the contact (5.2 s) above
    rec = read_recording(path)
    assert _last_step_contact(rec) is True
    assert summarize(rec)["ended_by"] == "cut_short"
    assert rec.episode()["end_on_collision"] == "false"
    with path.open("rb") as f:
        reader = make_reader(f)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = list(reader.iter_messages())
    del metadata["episode"]["end_on_collision"]
    older = read_recording(_write(tmp_path / "older.mcap", metadata, messages))
    assert summarize(older)["ended_by"] == "contact"
    ended = read_recording(_record(tmp_path / "ended", _chase, end_on_collision=True))
    assert ended.episode()["end_on_collision"] == "true" and summarize(ended)["ended_by"] == "contact"
