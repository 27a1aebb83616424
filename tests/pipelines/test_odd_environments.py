"""crowdmpc started where it cannot run as it would elsewhere. Under a locale whose encoding lacks the
characters its tables use (ASCII with Python's UTF-8 mode and locale coercion off, as some clusters' job
environments start it; Latin-1 lacks "—" and "−") a sweep ended in a UnicodeEncodeError as it wrote
table.md, its report unwritten, and a printed table could raise the same; in a removed folder, torch failed
to load."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ASCII = {"LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}


def _crowdmpc(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = os.environ | ASCII | {"PYTHONPATH": str(ROOT), "CROWDMPC_CACHE": str(cwd / "cache")}
    return subprocess.run(
        [sys.executable, "-m", "pipelines.cli", *args], cwd=cwd, env=env, capture_output=True, timeout=300
    )


def test_a_sweep_writes_its_report_as_utf8_under_an_ascii_locale(tmp_path):
    check = _crowdmpc([], tmp_path)  # usage only: the locale really is ASCII in the child
    assert check.returncode == 2
    probe = subprocess.run(
        [sys.executable, "-c", "import locale; print(locale.getpreferredencoding())"],
        env=os.environ | ASCII,
        capture_output=True,
        text=True,
    )
    assert probe.stdout.strip() in ("ANSI_X3.4-1968", "ascii", "US-ASCII")
    argv = ["sweep", "--experiment", "controllers", "--controllers", "straight", "--humans", "1"]
    done = _crowdmpc([*argv, "--episodes-per-cell", "1", "--backend", "inline", "--out", "s"], tmp_path)
    assert done.returncode == 0, done.stderr.decode(errors="replace")[-2000:]
    table = (tmp_path / "s" / "table.md").read_text(encoding="utf-8")
    assert "±" in table  # the interval of a travel time, written as itself


def test_a_printed_table_shows_what_the_locale_cannot_as_escapes(tmp_path):
    argv = ["sweep", "--experiment", "controllers", "--controllers", "straight", "--humans", "1"]
    for out in ("a", "b"):
        done = _crowdmpc([*argv, "--episodes-per-cell", "1", "--backend", "inline", "--out", out], tmp_path)
        assert done.returncode == 0
    compared = _crowdmpc(["compare", "a=a", "b=b", "--no-progress"], tmp_path)  # its table prints "−", "Δ"
    assert compared.returncode == 0, compared.stderr.decode(errors="replace")[-2000:]
    assert "+0 / \\u22120 (p = 1)" in compared.stdout.decode("ascii")  # nothing raw the locale cannot show


def test_a_removed_current_directory_is_one_line(tmp_path):
    """Started in a folder removed meanwhile (rmdir from another terminal), simulate stopped with oneMKL's
    "FATAL ERROR: Cannot load libtorch_cpu.so" as torch loaded."""
    gone = tmp_path / "gone"
    gone.mkdir()
    done = subprocess.run(
        [sys.executable, "-m", "pipelines.cli", "simulate", "--controller", "straight"],
        cwd=gone,
        preexec_fn=lambda: os.rmdir(gone),  # in the child, once it is inside the folder
        env=os.environ | {"PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr == (
        "crowdmpc: error: the current directory no longer exists (removed since the shell entered it); cd to "
        "another\n"
    )


def test_a_utf8_cache_path_under_an_ascii_locale_names_the_locale(tmp_path):
    """The path "café" is UTF-8 on disk, but an ASCII locale decodes it to surrogates, which CasADi cannot
    pass on: it was refused as "not UTF-8", sending the user to rename a folder whose name was fine."""
    code = "from mpc import compile_cache as c\ntry:\n c.writable_dir()\nexcept Exception as e:\n print(e)"
    cache = os.fsencode(tmp_path) + "/café".encode()
    env = os.environb | {k.encode(): v.encode() for k, v in ASCII.items()}
    env |= {b"PYTHONPATH": os.fsencode(ROOT), b"CROWDMPC_CACHE": cache}
    said = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, timeout=60)
    assert (
        b"is not text in this locale's encoding (ascii), which CasADi cannot pass to gcc: run under a "
        in (said.stdout)
    ), said.stdout + said.stderr
    assert b"UTF-8 locale (LANG=C.UTF-8) or name an ASCII path" in said.stdout
