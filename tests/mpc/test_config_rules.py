"""mpc/config_rules.py: a field that another field's value leaves unread is refused where it is not its
default, in one line naming it and the field that would read it, from MPCConfig, --set, a file and --vary:
`--set mpc.dmpc_relaxation=0.3` under Jacobi's update ran as 0.5 does, and `--vary
mpc.dmpc_relaxation=0.3,0.7` ran the same DMPC episodes twice under two cell keys."""

from __future__ import annotations

import pytest

from mpc.config import MPCConfig
from mpc.errors import MPCConfigError
from pipelines.cli import main


@pytest.mark.parametrize("update", ["jacobi", "gauss_seidel", "sequential_accept"])
def test_a_relaxation_without_the_relaxed_update_is_refused(update):
    with pytest.raises(MPCConfigError, match=f"dmpc_relaxation = 0.3 .*dmpc_update is '{update}'"):
        MPCConfig(dmpc_update=update, dmpc_relaxation=0.3)
    assert MPCConfig(dmpc_update=update).dmpc_relaxation == 0.5  # its default passes
    assert MPCConfig(dmpc_update="relaxed", dmpc_relaxation=0.3).dmpc_relaxation == 0.3


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["simulate", "--controller", "dmpc", "--set", "mpc.dmpc_relaxation=0.3"],
            "--set mpc.dmpc_relaxation: dmpc_relaxation = 0.3 sizes the relaxed update's step; dmpc_update "
            "is 'jacobi'",
        ),
        (
            ["sweep", "--experiment", "controllers", "--vary", "mpc.dmpc_relaxation=0.3,0.7", "--dry-run"],
            "--vary value 0.3: dmpc_relaxation = 0.3 sizes the relaxed update's step",
        ),
    ],
)
def test_the_command_line_refuses_it_in_one_line(tmp_path, capsys, options, message):
    if options[0] == "sweep":
        options = [*options, "--out", str(tmp_path / "s")]
    assert main(options) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_file_names_itself(tmp_path, capsys):
    path = tmp_path / "run.toml"
    path.write_text("[mpc]\ndmpc_relaxation = 0.25\n")
    assert main(["--config", str(path), "config", "show"]) == 2
    assert f"{path}: mpc.dmpc_relaxation: dmpc_relaxation = 0.25" in capsys.readouterr().err
