"""docs/extending.md, run as written: every ``crowdmpc`` command of its bash blocks, in order, in a directory
holding only the guide's example files (its predictor, and section 6's controller as the page prints it), with
fewer epochs and episodes (the only edits), each must succeed. So the guide cannot go stale: a changed
option, a renamed file or a broken step fails this test."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.predictors.samples import shared_data_dir

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "extending.md"
EXAMPLE = ROOT / "docs" / "examples" / "window_mlp.py"
# Smaller runs than the guide's (CI has 2 cores); nothing else in a command is changed.
SHORTER = {
    r"--epochs \d+": "--epochs 1",
    r"--episodes-per-cell \d+": "--episodes-per-cell 2",
    r"--episodes \d+": "--episodes 1",
}


def guide_commands() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", GUIDE.read_text(), flags=re.S)
    commands = []
    for block in blocks:
        for command in block.replace("\\\n", " ").splitlines():
            if command.strip().startswith("crowdmpc "):
                for pattern, replacement in SHORTER.items():
                    command = re.sub(pattern, replacement, command)
                commands.append(command.strip())
    return commands


def controller_file() -> str:
    """Section 6's controller, ``my_controller.py``: the one python block of that section."""
    text = GUIDE.read_text()
    section = re.search(r"^## 6\. .*?(?=^## )", text, flags=re.S | re.M)
    assert section is not None, "docs/extending.md has no section 6"
    (code,) = re.findall(r"```python\n(.*?)```", section.group(0), flags=re.S)
    return code


def test_the_guide_has_every_step():
    steps = [shlex.split(c)[1:4] for c in guide_commands()]  # crowdmpc --plugin X <command>
    mlp, mine = ["--plugin", "window_mlp:WindowMLP"], ["--plugin", "my_controller:GoStraight"]
    assert steps == [
        *([*mlp, step] for step in ("train", "zoo", "evaluate", "export", "simulate", "sweep", "calibrate")),
        [*mlp, "simulate"],  # with the margins calibrated
        ["compare", "none=runs/window_mlp_eth.json", "cp0.2=runs/window_mlp_eth-cp.json"],
        ["review", "runs/window_mlp_eth-cp"],
        *([*mine, step] for step in ("simulate", "sweep")),  # section 6: the controller
    ]
    assert "class GoStraight:" in controller_file()


def test_the_guide_runs_from_its_own_directory(tmp_path):
    data = shared_data_dir()
    if data is None:
        pytest.skip("shared data (../shared/data or $CROWDMPC_DATA) not available")
    work = tmp_path / "my_project"
    work.mkdir()
    shutil.copy(EXAMPLE, work / EXAMPLE.name)  # the user's files, outside the package
    (work / "my_controller.py").write_text(controller_file())
    env = {
        **os.environ,
        "CROWDMPC_DATA": str(data),
        "CROWDMPC_ZOO": str(tmp_path / "zoo"),
        "CROWDMPC_CACHE": str(tmp_path / "cache"),
        "PYTHONPATH": str(ROOT),
    }
    env.pop("CROWDMPC_PLUGINS", None)
    outputs = []
    for command in guide_commands():
        argv = [a.replace("$CROWDMPC_DATA", str(data)) for a in shlex.split(command)]
        done = subprocess.run(
            [sys.executable, "-m", "pipelines.cli", *argv[1:]],
            cwd=work,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0, f"{command}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        outputs.append(done.stdout)
    assert re.search(r"parity with torch \(float64\): values \S+, Jacobians", "".join(outputs))
    table = (work / "runs" / "swap-window-mlp" / "table.md").read_text()
    assert "window_mlp_eth" in table and "social_lstm_eth" in table
    assert (tmp_path / "zoo" / "window_mlp_eth.pt").is_file()
    assert "window_mlp_eth" in (tmp_path / "zoo" / "calibrations.json").read_text()
    assert "| cmpc | 7 | 3 | cp0.2 | 1 |" in "".join(outputs)  # compare paired the runs' one episode
    assert not (ROOT / "checkpoints" / "window_mlp_eth.pt").exists()
    assert (
        "| orca | cmpc | my_controller:GoStraight |"
        in (work / "runs" / "controllers-mine" / "table.md").read_text()
    )
