"""The installable package: pyproject.toml lists every package, and a wheel built from a copy of the sources,
installed into a fresh virtual environment and run outside the clone, has the shipped model zoo, runs, and
shows its types to mypy.

The fresh environment takes the heavy dependencies (torch, CasADi, ...) from the running interpreter's
site-packages through a ``.pth`` line: a plain path line adds that directory to ``sys.path`` without
processing its own ``.pth`` files, so an editable install of this clone there (its import finder) stays out,
and the wheel's copy, in the fresh environment's site-packages, comes first.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
import zipfile
from pathlib import Path

from predictors import zoo
from predictors.manifest import LOCK_NAME

ROOT = Path(__file__).resolve().parents[1]
SOURCE_TREES = ("crowdsim", "mpc", "pipelines", "predictors")


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_pyproject_lists_every_package_and_maps_the_shipped_zoo():
    """A package missing from the explicit list would be missing from the wheel only, not from a clone."""
    setuptools = _pyproject()["tool"]["setuptools"]
    on_disk = {
        ".".join(path.relative_to(ROOT).parts)
        for tree in SOURCE_TREES
        for path in [ROOT / tree, *(ROOT / tree).rglob("*")]
        if path.is_dir() and path.name != "__pycache__" and any(path.glob("*.py"))
    }
    listed = set(setuptools["packages"])
    assert on_disk - listed == set(), "add these to [tool.setuptools] packages in pyproject.toml"
    assert listed - on_disk == {zoo.CHECKPOINTS_PACKAGE}
    assert setuptools["package-dir"] == {zoo.CHECKPOINTS_PACKAGE: zoo.CHECKPOINTS_DIRNAME}
    assert (ROOT / zoo.CHECKPOINTS_DIRNAME / "__init__.py").is_file()  # a regular package: files() is a Path


def test_every_source_package_is_marked_typed():
    """PEP 561: without ``py.typed`` mypy treats an installed package as untyped and a user's own code that
    imports it fails to check (``import-not-found``); the subpackages are covered by their top package's."""
    assert [tree for tree in SOURCE_TREES if not (ROOT / tree / "py.typed").is_file()] == []


def test_citation_file_names_the_version_and_licence_pyproject_declares():
    """CITATION.cff repeats two of pyproject's facts; a release that bumps one must bump the other."""
    project = _pyproject()["project"]
    top_level = [line for line in (ROOT / "CITATION.cff").read_text().splitlines() if line[:1].isalpha()]
    fields = dict(line.split(": ", 1) for line in top_level if ": " in line)
    assert (fields["version"], fields["license"]) == (project["version"], project["license"])


def test_a_clone_reads_its_own_checkpoints(monkeypatch):
    monkeypatch.delenv(zoo.CHECKPOINTS_ENV, raising=False)
    assert zoo.checkpoints_dir() == ROOT / zoo.CHECKPOINTS_DIRNAME
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, "/elsewhere")
    assert zoo.checkpoints_dir() == Path("/elsewhere")


def _build_wheel(tmp: Path) -> Path:
    """A wheel built from a copy of the sources (the clone is left alone: no build/ or egg-info written in
    it). With ``build`` installed: sdist first, then the wheel from the sdist, as CI does; else pip wheel."""
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    for tree in (*SOURCE_TREES, zoo.CHECKPOINTS_DIRNAME):
        shutil.copytree(ROOT / tree, src / tree, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    dist = tmp / "dist"
    if importlib.util.find_spec("build") is not None:
        command = [sys.executable, "-m", "build", "--no-isolation", "--outdir", str(dist), str(src)]
    else:
        command = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w", str(dist)]
        command.append(str(src))
    done = subprocess.run(command, capture_output=True, text=True, cwd=tmp)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    (wheel,) = dist.glob("crowdmpc-*.whl")
    return wheel


def _fresh_env(tmp: Path, wheel: Path) -> tuple[Path, Path]:
    """A new virtual environment with the wheel installed; (its bin directory, its site-packages)."""
    env_dir = tmp / "env"
    venv.EnvBuilder(with_pip=False, symlinks=True).create(env_dir)
    python = env_dir / "bin" / "python"
    purelib = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    # the running interpreter's pip installs into the new environment (which has none of its own)
    install = [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index"]
    done = subprocess.run([*install, "--quiet", str(wheel)], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    # only now (pip must not see the clone's editable install): the dependencies, after the new site-packages
    deps = sysconfig.get_paths()["purelib"]
    (Path(purelib) / "_crowdmpc_test_dependencies.pth").write_text(deps + "\n")
    return env_dir / "bin", Path(purelib)


def _run(command: list[str], cwd: Path, env: dict[str, str]) -> str:
    done = subprocess.run(command, capture_output=True, text=True, cwd=cwd, env=env, timeout=300)
    assert done.returncode == 0, f"{command}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done.stdout


# What the installed code reports about itself: where its modules and zoo are, and the calibrations it reads.
PROBE = """
import json, sys
import crowdmpc_checkpoints, pipelines, predictors
from predictors import zoo
from predictors.calibration_store import calibration_files, read_calibrations
print(json.dumps({
    "modules": [m.__file__ for m in (predictors, pipelines, crowdmpc_checkpoints)],
    "project_modules": sorted({
        str(getattr(m, "__file__", None)) for name, m in sys.modules.items()
        if name.split(".")[0] in ("predictors", "pipelines", "mpc", "crowdsim", "crowdmpc_checkpoints")
    }),
    "checkpoints": str(zoo.checkpoints_dir()),
    "zoo": zoo.zoo_names(),
    "calibration_files": [str(p) for p in calibration_files()],
    "calibrations": len(read_calibrations()),
}))
"""


def test_the_wheel_runs_outside_the_clone(tmp_path):
    wheel = _build_wheel(tmp_path)
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    # not the zoo's lock, which a maintainer's `zoo add --shipped` leaves in a clone (ignored by git)
    shipped = {
        p.name for p in (ROOT / zoo.CHECKPOINTS_DIRNAME).iterdir() if p.is_file() and p.name != LOCK_NAME
    }
    assert {f"{zoo.CHECKPOINTS_PACKAGE}/{name}" for name in shipped} <= names  # every .pt, .json, README
    data_files = {
        path.relative_to(ROOT).as_posix()
        for tree in SOURCE_TREES
        for path in (ROOT / tree).rglob("*")
        if path.is_file() and path.suffix not in (".py", ".pyc")
    }
    assert data_files - names == set(), (
        "package data missing from the wheel: see [tool.setuptools.package-data]"
    )
    assert not any(n.startswith(("tests/", "benchmarks/", "checkpoints/", "data/")) for n in names)
    # MIT asks that copies keep the licence text: pyproject's license-files puts it in the wheel's metadata
    (licence,) = [n for n in names if n.endswith(".dist-info/licenses/LICENSE")]
    with zipfile.ZipFile(wheel) as archive:
        assert archive.read(licence) == (ROOT / "LICENSE").read_bytes()

    bin_dir, site = _fresh_env(tmp_path, wheel)
    work = tmp_path / "work"  # outside the clone, so that the clone is not on sys.path through the cwd
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "CROWDMPC_"))}
    env |= {"CROWDMPC_ZOO": str(tmp_path / "user_zoo"), "CROWDMPC_CACHE": str(tmp_path / "cache")}
    before = {p: p.stat().st_mtime_ns for p in (site / zoo.CHECKPOINTS_PACKAGE).iterdir() if p.is_file()}

    probe = json.loads(_run([str(bin_dir / "python"), "-c", PROBE], work, env))
    for path in [*probe["modules"], *probe["project_modules"], probe["checkpoints"]]:
        assert Path(path).is_relative_to(site), f"{path} is not the wheel's copy in {site}"
    assert probe["checkpoints"] == str(site / zoo.CHECKPOINTS_PACKAGE)
    assert "social_lstm_eth" in probe["zoo"]
    user_file = str(tmp_path / "user_zoo" / "calibrations.json")
    assert probe["calibration_files"] == [
        user_file,
        str(site / zoo.CHECKPOINTS_PACKAGE / "calibrations.json"),
    ]
    assert probe["calibrations"] > 0  # the shipped ones, read from the installed package

    verify = _run([str(bin_dir / "crowdmpc"), "zoo", "verify"], work, env)
    assert "social_lstm_eth: ok" in verify and "problem" not in verify.lower()
    simulate = [
        str(bin_dir / "crowdmpc"),
        "simulate",
        "--controller",
        "cmpc",
        "--predictor",
        "social_lstm_eth",
    ]
    simulate += ["--humans", "3", "--episodes", "1", "--no-progress", "--record", "runs"]
    out = _run(simulate, work, env)
    assert "predictor social_lstm_eth" in out and "success" in out
    (recording,) = (work / "runs").glob("*.mcap")
    review = _run([str(bin_dir / "crowdmpc"), "review", str(recording), "--check"], work, env)
    assert "social_lstm_eth" in review and ", ok" in review

    after = {p: p.stat().st_mtime_ns for p in (site / zoo.CHECKPOINTS_PACKAGE).iterdir() if p.is_file()}
    assert after == before  # nothing written into the installed package
    _check_types_seen_by_mypy(bin_dir / "python", work)


# A user's code with two type errors that mypy can see only through the installed package's annotations.
USER_CODE = """
from crowdsim.world import RADIUS
from mpc.config import MPCConfig

radius: str = RADIUS
MPCConfig(horizon="13")
"""


def _check_types_seen_by_mypy(python: Path, work: Path) -> None:
    """mypy, run on a user's file against the fresh environment, finds the wheel's modules and their types."""
    if importlib.util.find_spec("mypy") is None:
        return  # the dev extra brings mypy; a bare install has nothing to check with
    user = work / "user_code.py"
    user.write_text(USER_CODE)
    command = [sys.executable, "-m", "mypy", "--python-executable", str(python), "--no-error-summary"]
    command += ["--cache-dir", str(work / "mypy_cache"), user.name]
    done = subprocess.run(command, capture_output=True, text=True, cwd=work)
    errors = sorted(line.split("error: ")[1] for line in done.stdout.splitlines() if "error: " in line)
    assert errors == [
        'Argument "horizon" to "MPCConfig" has incompatible type "str"; expected "int"  [arg-type]',
        'Incompatible types in assignment (expression has type "float", variable has type "str")'
        "  [assignment]",
    ], done.stdout + done.stderr
