"""The persistent compile cache: compiled once, loaded after, identical solves, safe under concurrency."""

import contextlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpc import cache_admin, compile_cache, solvers
from mpc.cache_entries import LEFTOVER_AGE_S, discard, intact, load_solver, locked, remove_dead_leftovers
from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.fallback import PlanMemory
from mpc.nlp import StepData
from predictors.base import DT
from tests.mpc.reactive import ReactivePredictor

needs_gcc = pytest.mark.skipif(compile_cache.compiler() is None, reason="gcc is not on the PATH")
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    """A private $CROWDMPC_CACHE, and a private working directory (to see what is written into it)."""
    monkeypatch.setenv(compile_cache.CACHE_ENV, str(tmp_path / "cache"))
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    return tmp_path / "cache" / compile_cache.SUBDIR


def small_nlp(weight: float = 1.0) -> dict:
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p", 2)
    return {"x": x, "p": p, "f": weight * ca.sumsqr(x - p) + ca.sumsqr(ca.sin(x)), "g": x[0] + x[1]}


IPOPT = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes"}


def assert_solves_as_casadi(solver: ca.Function) -> None:
    """``solver`` (of small_nlp()) finds the minimum CasADi's own, uncompiled solver finds."""
    args = {"x0": 0, "p": [1, 2], "lbg": -1, "ubg": 1}
    expected = ca.nlpsol("s", "ipopt", small_nlp(), IPOPT)(**args)["x"]
    np.testing.assert_allclose(solver(**args)["x"], expected, rtol=0, atol=1e-9)


def no_compile(*args) -> None:
    raise AssertionError("compiled again")


def suffixes(folder: Path) -> list[str]:
    """The cache's files by type, lock files left out."""
    return sorted(p.suffix for p in folder.iterdir() if p.suffix != ".lock")


# --- CMPC: the same solves cold, warm and without the cache ------------------------------------------------


def crossing_case():
    """Two robots heading north, two humans walking south between them and reacting to the robots."""
    states = np.array([[-0.6, -3.0, 0, 0.5], [0.6, -3.0, 0, 0.5]], dtype=float)
    data = StepData(states, np.zeros((2, 2)), states[:, :2] + [0.0, 6.0], np.ones(2, dtype=bool))
    now = np.concatenate([states[:, :2], [[-0.3, 0.0], [0.5, 0.4]]])
    history = np.stack([now + [0.0, DT], now])
    mask = np.ones(history.shape[:2], dtype=bool)
    predictor = ReactivePredictor(gain=0.3)
    return data, lambda robots_future: predictor.rollout(history, mask, robots_future, np.array([2, 3]))


def cmpc_steps(solver: CMPC, steps: int = 3) -> list:
    """A few control steps from standing (the first explores with both solvers), warm-started after."""
    data, predict = crossing_case()
    memory = PlanMemory(solver.cfg)
    results = []
    for _ in range(steps):
        result = solver.solve(data, predict, memory.start(data))
        memory.commit(result.accels, result.solved, result.lam_x, result.lam_g)
        results.append(result)
    return results


def assert_same(a: list, b: list) -> None:
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.accels, y.accels)
        np.testing.assert_array_equal(x.lam_x, y.lam_x)
        assert (x.potentials, x.iterations, x.solves, x.solver_iterations, x.status) == (
            y.potentials, y.iterations, y.solves, y.solver_iterations, y.status
        )  # fmt: skip


@needs_gcc
def test_cmpc_solves_the_same_cold_warm_and_without_the_cache(cache, monkeypatch):
    cfg = MPCConfig(jit=True)
    compiles = []
    compile_nlpsol = compile_cache._compile_nlpsol
    monkeypatch.setattr(
        compile_cache, "_compile_nlpsol", lambda *a: compiles.append(a[0]) or compile_nlpsol(*a)
    )
    cold = cmpc_steps(CMPC(cfg, 2, 2))
    assert compiles == ["joint_2r_2h"]  # the Fatrop solver; the IPOPT fallback is not compiled
    warm = cmpc_steps(CMPC(cfg, 2, 2))
    assert compiles == ["joint_2r_2h"]  # loaded, not compiled again
    assert suffixes(cache) == [".casadi", ".record", ".so"]  # one entry: a solver, its library and record
    assert not list(Path.cwd().iterdir())  # no generated source left in the working directory

    def plain_jit(name, plugin, nlp, options, jit):  # CasADi's own jit, as before the cache
        jit_options = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O2"], "verbose": False}}
        return ca.nlpsol(name, plugin, nlp, options | (jit_options if jit else {}))

    monkeypatch.setattr(solvers, "build_nlpsol", plain_jit)
    uncached = cmpc_steps(CMPC(cfg, 2, 2))
    assert all(r.solved for r in cold) and cold[0].iterations > 1
    assert_same(cold, warm)
    assert_same(cold, uncached)


# --- nlpsol entries --------------------------------------------------------------------------------------


@needs_gcc
def test_an_entry_is_a_solver_and_its_library_published_complete(cache):
    solver = compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    files = {p.suffix: p.name for p in cache.iterdir()}
    key = files[".casadi"].removesuffix(".casadi")
    assert len(key) == 64 and sorted(files) == [".casadi", ".lock", ".record", ".so"]
    assert files[".lock"] == f"{key}.lock" and files[".so"].startswith(f"{key}.")  # <key>.<pid>_<random>.so
    assert files[".record"] == f"{key}.record"
    again = compile_cache.nlpsol("another_name", "ipopt", small_nlp(), IPOPT)  # the name is not in the key
    assert len(list(cache.iterdir())) == 4
    out = [
        s(x0=0, p=[1, 2], lbg=-1, ubg=1) for s in (solver, again, ca.nlpsol("s", "ipopt", small_nlp(), IPOPT))
    ]
    np.testing.assert_array_equal(out[0]["x"], out[1]["x"])
    np.testing.assert_allclose(out[0]["x"], out[2]["x"], atol=1e-9)


@needs_gcc
def test_the_key_covers_the_nlp_options_casadi_compiler_and_directory(monkeypatch, tmp_path):
    cc = compile_cache.compiler()
    key = compile_cache.nlp_key("ipopt", small_nlp(), IPOPT, cc, tmp_path)
    assert compile_cache.nlp_key("ipopt", small_nlp(), IPOPT, cc, tmp_path) == key  # a graph built again
    assert compile_cache.nlp_key("ipopt", small_nlp(2.0), IPOPT, cc, tmp_path) != key
    assert compile_cache.nlp_key("fatrop", small_nlp(), IPOPT, cc, tmp_path) != key
    assert compile_cache.nlp_key("ipopt", small_nlp(), IPOPT | {"ipopt.tol": 1e-3}, cc, tmp_path) != key
    other_flags = compile_cache.Compiler(cc.path, cc.version, ("-O3",))
    assert compile_cache.nlp_key("ipopt", small_nlp(), IPOPT, other_flags, tmp_path) != key
    assert compile_cache.nlp_key("ipopt", small_nlp(), IPOPT, cc, tmp_path / "moved") != key
    monkeypatch.setattr(ca, "__version__", "0.0.0")
    assert compile_cache.nlp_key("ipopt", small_nlp(), IPOPT, cc, tmp_path) != key


@needs_gcc
def test_an_entry_whose_library_is_gone_is_compiled_again(cache):
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    (library,) = cache.glob("*.so")
    library.unlink()
    solver = compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    assert len(list(cache.glob("*.so"))) == 1 and not library.exists()
    assert_solves_as_casadi(solver)


LOAD = """
import sys
sys.path.insert(0, {root!r})
import casadi as ca
from mpc import compile_cache
from tests.mpc.test_compile_cache import IPOPT, small_nlp
solver = compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT, directory={folder!r})
print(solver(x0=0, p=[1, 2], lbg=-1, ubg=1)["x"])
"""


def load_in_a_child(folder: Path) -> subprocess.CompletedProcess:
    """nlpsol of small_nlp() from ``folder`` in a process of its own: loading a truncated library used to be
    a bus error, which would take pytest with it."""
    script = LOAD.format(root=str(ROOT), folder=str(folder))
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)


@needs_gcc
@pytest.mark.parametrize("damage", ["truncate", "flip a byte", "no record", "record of another library"])
def test_an_entry_whose_library_is_not_the_one_stored_is_compiled_again(cache, damage, monkeypatch):
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    (library,) = cache.glob("*.so")
    (record,) = cache.glob("*.record")
    data = library.read_bytes()
    if damage == "truncate":
        library.write_bytes(data[: len(data) // 3])
    elif damage == "flip a byte":
        library.write_bytes(data[:100] + bytes([data[100] ^ 1]) + data[101:])
    elif damage == "no record":  # an entry stored before records were kept
        record.unlink()
    else:
        record.write_text(record.read_text().replace(library.name, "../elsewhere.so"))
    child = load_in_a_child(cache)
    assert child.returncode == 0, child.stderr[-500:]
    assert len(set(cache.glob("*.so")) - {library}) == 1  # compiled again
    # The damaged library goes with its entry; one no valid record names is left to `cache clear`.
    assert library.exists() == (damage in ("no record", "record of another library"))
    monkeypatch.setattr(compile_cache, "_compile_nlpsol", no_compile)  # the child's new entry loads here
    assert_solves_as_casadi(compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT))


@needs_gcc
def test_the_jit_options_belong_to_the_cache(cache):
    with pytest.raises(ValueError, match="jit_options"):
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT | {"jit_options": {"flags": ["-O3"]}})


def test_no_gcc_is_an_error_naming_it(cache, monkeypatch):
    monkeypatch.setattr(compile_cache, "compiler", lambda: None)
    with pytest.raises(compile_cache.CompileCacheError, match="gcc on the PATH"):
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)


CHILD = """
import sys
sys.path.insert(0, {root!r})
import casadi as ca
from mpc import compile_cache
compiled = []
compile = compile_cache._compile_nlpsol
compile_cache._compile_nlpsol = lambda *a: compiled.append(1) or compile(*a)
x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 3)
f = ca.sumsqr(x - p) + ca.sumsqr(ca.sin(x)) + ca.sumsqr(ca.cos(3 * x))
options = {{"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes"}}
solver = compile_cache.nlpsol("s", "ipopt", {{"x": x, "p": p, "f": f, "g": ca.sum1(x)}}, options)
print(len(compiled), float(solver(x0=0, p=[1, 2, 3], lbg=-1, ubg=1)["f"]))
"""


@needs_gcc
def test_concurrent_workers_compile_an_entry_once(cache, tmp_path):
    script = tmp_path / "child.py"
    script.write_text(textwrap.dedent(CHILD.format(root=str(ROOT))))
    env = os.environ | {compile_cache.CACHE_ENV: str(cache.parent)}
    children = [
        subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env)
        for _ in range(3)
    ]
    outputs = [child.communicate(timeout=300)[0].split() for child in children]
    assert all(child.returncode == 0 for child in children)
    assert sorted(int(o[0]) for o in outputs) == [0, 0, 1]  # one compiled, the others waited and loaded
    assert len({o[1] for o in outputs}) == 1
    assert suffixes(cache) == [".casadi", ".record", ".so"]  # and no temporaries


# --- info and clear -----------------------------------------------------------------------------------------


def test_info_and_clear_touch_only_our_files(tmp_path):
    folder = tmp_path / "compiled"
    folder.mkdir()
    key = "ab" * 32
    ours = [f"{key}.casadi", f"{key}.123_ab12cd34.so", f"{key}.123_ab12cd34.o", f"{key}.lock"]
    ours += [f"{key}.record", f".tmp-{key}.77_0123abcd.record"]
    ours += [f".tmp-{key}.77_0123abcd.casadi", "crowdmpc_jit_77_0123abcd.c"]  # what a killed compile leaves
    for name in ours:
        (folder / name).write_bytes(b"x" * 10)
    outside = tmp_path / "precious.so"
    outside.write_bytes(b"keep")
    (folder / f"{'cd' * 32}.casadi").symlink_to(outside)  # named like ours, but a link: left alone
    (folder / "notes.txt").write_text("not ours")
    (folder / f"{key}.so").write_text("not a name of ours")
    (folder / f"{'ef' * 32}.casadi").mkdir()  # a folder named like an entry
    stats = cache_admin.info(folder)
    assert (stats.entries, stats.files, stats.size_bytes) == (1, 8, 80)
    assert stats.casadi_version == ca.__version__
    assert cache_admin.clear(folder) == (8, 80, 0)
    left = [f"{'cd' * 32}.casadi", "notes.txt", f"{'ef' * 32}.casadi", f"{key}.so"]
    assert sorted(p.name for p in folder.iterdir()) == sorted(left)
    assert outside.read_bytes() == b"keep"
    assert cache_admin.info(folder).entries == 0


def test_clear_leaves_an_entry_another_process_compiles_now(tmp_path):
    """`crowdmpc cache clear` while a sweep compiled removed the compile's files under it ("ld: cannot find
    <key>.<tag>.o", "cc1: fatal error: crowdmpc_jit_<tag>.c: No such file or directory") and its episodes
    raised. The compile holds its entry's lock (another open file here: flock locks are per open file)."""
    busy, done = "ab" * 32, "cd" * 32
    compiling = [f"{busy}.lock", "crowdmpc_jit_77_0123abcd.c", f"{busy}.77_0123abcd.o"]
    compiling += [f".tmp-{busy}.77_0123abcd.casadi", f"{busy}.77_0123abcd.so"]
    stored = [f"{done}.lock", f"{done}.casadi", f"{done}.record", f"{done}.55_89abcdef.so"]
    for name in compiling + stored:
        (tmp_path / name).write_bytes(b"x" * 10)
    with locked(tmp_path / f"{busy}.lock"):
        assert cache_admin.clear(tmp_path) == (4, 40, 1)
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(compiling)
    assert cache_admin.clear(tmp_path) == (5, 50, 0)  # once it is done
    assert list(tmp_path.iterdir()) == []


def test_clear_refuses_a_cache_directory_that_is_a_symlink(tmp_path):
    target = tmp_path / "elsewhere"
    target.mkdir()
    (target / f"{'ab' * 32}.casadi").write_text("x")
    link = tmp_path / "compiled"
    link.symlink_to(target)
    with pytest.raises(compile_cache.CompileCacheError, match="symlink"):
        cache_admin.clear(link)
    assert (target / f"{'ab' * 32}.casadi").exists()


def test_clear_names_a_file_it_may_not_remove(tmp_path, monkeypatch):
    """A cache folder the user may not write gave "[Errno 13] Permission denied: '<path>.so'" (root ignores
    the folder's mode, so the refusal is the one unlink gives a user)."""
    key = "ab" * 32
    for name in (f"{key}.casadi", f"{key}.record", f"{key}.lock"):
        (tmp_path / name).write_bytes(b"x" * 10)
    real_unlink = os.unlink

    def unlink(path, *args, **kwargs):
        if str(path).endswith(".record"):
            raise PermissionError(13, "Permission denied", str(path))
        real_unlink(path, *args, **kwargs)

    monkeypatch.setattr(cache_admin.os, "unlink", unlink)
    with pytest.raises(compile_cache.CompileCacheError) as raised:
        cache_admin.clear(tmp_path)
    assert (
        str(raised.value)
        == f"cannot remove {tmp_path / (key + '.record')} (Permission denied); 1 file removed before it"
    )


def test_the_cache_lives_under_crowdmpc_cache(monkeypatch, tmp_path):
    from predictors.data.locate import cache_root

    monkeypatch.setenv(compile_cache.CACHE_ENV, str(tmp_path))
    assert compile_cache.cache_dir() == cache_root() / "compiled" == tmp_path / "compiled"
    monkeypatch.delenv(compile_cache.CACHE_ENV)
    assert compile_cache.cache_dir() == cache_root() / "compiled"


@needs_gcc
def test_a_cache_the_shell_would_split_is_refused_and_nothing_is_written_outside_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(compile_cache.CacheLocationError, match="holds a space or shell character"):
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT, directory=tmp_path / "my cache")
    assert list(tmp_path.iterdir()) == []  # gcc used to write tmp_path/"my" (the path before the space)


def test_a_failed_compile_is_a_compile_cache_error(cache, monkeypatch, tmp_path):
    failing = tmp_path / "gcc"
    failing.write_text("#!/bin/sh\nexit 1\n")
    failing.chmod(0o755)
    broken = compile_cache.Compiler(str(failing), "x", ("-O2",))
    monkeypatch.setattr(compile_cache, "compiler", lambda: broken)
    with pytest.raises(
        compile_cache.CompileCacheError, match=r"compiling the solver 's' into .* failed: "
    ) as e:
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    assert suffixes(cache) == []  # nothing but the lock left
    # the compile CasADi tried, as the user would type it: not the shell that watches for Ctrl-C around it
    assert f'Tried "{failing} -O2 ' in str(e.value) and "trap" not in str(e.value)


def test_a_compiler_gone_since_it_was_found_is_a_failed_compile(cache, monkeypatch, tmp_path):
    """gcc is run here, not by a shell that said "not found" (127): one removed since ``compiler()`` found it
    is still a failed compile, not an OSError out of the compile."""
    gone = compile_cache.Compiler(str(tmp_path / "gcc"), "x", ("-O2",))
    monkeypatch.setattr(compile_cache, "compiler", lambda: gone)
    with pytest.raises(compile_cache.CompileCacheError, match="Compilation failed"):
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    assert suffixes(cache) == []


def test_a_compile_failed_for_want_of_space_is_a_full_disk_naming_the_cache(cache, monkeypatch, tmp_path):
    """gcc's "No space left on device" reached the user as "Compilation failed" with a traceback (a
    CompileCacheError is no user error); the CLI says a full disk in one line, naming the folder."""
    import errno

    failing = tmp_path / "gcc"
    ran = tmp_path / "gcc-ran"
    failing.write_text(f"#!/bin/sh\ntouch {ran}\necho 'Fatal error: No space left on device' >&2\nexit 1\n")
    failing.chmod(0o755)
    full = compile_cache.Compiler(str(failing), "x", ("-O2",))
    monkeypatch.setattr(compile_cache, "compiler", lambda: full)
    room = compile_cache.COMPILE_ROOM_BYTES
    monkeypatch.setattr(compile_cache, "free_bytes", lambda folder: room - ran.exists())  # gcc filled it
    with pytest.raises(OSError) as e:
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    assert (e.value.errno, e.value.filename) == (errno.ENOSPC, str(cache))
    assert suffixes(cache) == []
    monkeypatch.setattr(compile_cache, "free_bytes", lambda folder: compile_cache.COMPILE_ROOM_BYTES)
    with pytest.raises(compile_cache.CompileCacheError, match="Compilation failed"):  # gcc failed with room
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)


def test_no_compile_starts_without_room_for_it(cache, monkeypatch, tmp_path, capfd):
    """simulate --set mpc.jit=true with the cache's disk full printed gcc's errors on the source it had cut
    short above the CLI's line: under COMPILE_ROOM_BYTES free, no compile starts (as the sweep's check)."""
    import errno

    ran = tmp_path / "gcc-ran"
    script = tmp_path / "gcc"
    script.write_text(f"#!/bin/sh\ntouch {ran}\necho 'x.c:1:1: error: expected declaration' >&2\nexit 1\n")
    script.chmod(0o755)
    monkeypatch.setattr(compile_cache, "compiler", lambda: compile_cache.Compiler(str(script), "x", ("-O2",)))
    monkeypatch.setattr(compile_cache, "free_bytes", lambda folder: compile_cache.COMPILE_ROOM_BYTES - 1)
    with pytest.raises(OSError) as e:
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    assert (e.value.errno, e.value.filename) == (errno.ENOSPC, str(cache))
    assert not ran.exists() and "error:" not in capfd.readouterr().err
    assert suffixes(cache) == []


def fake_compiler(tmp_path: Path, body: str) -> compile_cache.Compiler:
    script = tmp_path / "gcc"
    script.write_text(f"#!/bin/sh\n{body}\n")
    script.chmod(0o755)
    return compile_cache.Compiler(str(script), "x", ("-O2",))


def test_a_compiler_stopped_by_sigint_is_an_interrupt_not_a_failed_compile(
    cache, monkeypatch, tmp_path, sigint_as_at_a_terminal
):
    stopped = fake_compiler(tmp_path, "kill -INT $$")
    monkeypatch.setattr(compile_cache, "compiler", lambda: stopped)
    with pytest.raises(KeyboardInterrupt):
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    assert suffixes(cache) == []  # the marker gone with the other temporaries


def test_ctrl_c_in_a_relative_cache_directory_is_an_interrupt(
    cache, monkeypatch, tmp_path, sigint_as_at_a_terminal
):
    """The marker was named relative to the working directory the compile leaves for the cache folder: with
    $CROWDMPC_CACHE relative, the shell could not write it and the Ctrl-C was a failed compile again."""
    stopped = fake_compiler(tmp_path, "kill -INT $$")
    monkeypatch.setattr(compile_cache, "compiler", lambda: stopped)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(KeyboardInterrupt):
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT, directory="relative_cache")
    assert [p.suffix for p in (tmp_path / "relative_cache").iterdir()] == [".lock"]


INTERRUPTED = """
import sys
sys.path.insert(0, {root!r})
from mpc import compile_cache
from tests.mpc.test_compile_cache import IPOPT, small_nlp
compile_cache.compiler = lambda: compile_cache.Compiler({gcc!r}, "x", ("-O2",))
try:
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
except BaseException as exc:
    print(type(exc).__name__)
"""


def at_a_slow_compile(cache: Path, tmp_path: Path, template: str) -> tuple[subprocess.Popen, Path]:
    """A child process running ``template`` (its root and gcc filled in), in a session of its own, once its
    compile runs gcc, a stand-in that sleeps 60 s (up to 2 min to get there on a loaded host): the child, and
    the file holding the stand-in's pid. (30 s ran out on a host running two suites: the signal came in
    CasADi's code generation, whose C++ call held Python's handler, and the child sat out the compile.)"""
    gcc_pid = tmp_path / "gcc.pid"
    slow = fake_compiler(tmp_path, f"echo $$ > {gcc_pid}.new; mv {gcc_pid}.new {gcc_pid}; exec sleep 60")
    script = tmp_path / "child.py"
    script.write_text(textwrap.dedent(template.format(root=str(ROOT), gcc=slow.path)))
    env = os.environ | {compile_cache.CACHE_ENV: str(cache.parent)}
    child = subprocess.Popen(
        [sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env, start_new_session=True
    )
    for _ in range(2400):
        if gcc_pid.exists() or child.poll() is not None:
            break
        time.sleep(0.05)
    return child, gcc_pid


def test_ctrl_c_during_a_cold_compile_interrupts_the_program(cache, tmp_path, sigint_as_at_a_terminal):
    """CasADi compiled with system(), which ignores SIGINT in the caller while gcc runs: a Ctrl-C stopped gcc
    alone, and the program went on to report "compiling the solver ... failed" (a sweep: a failed cell)."""
    child, _ = at_a_slow_compile(cache, tmp_path, INTERRUPTED)
    os.killpg(child.pid, signal.SIGINT)  # what the terminal sends the foreground process group
    out, _ = child.communicate(timeout=60)
    assert out.split() == ["KeyboardInterrupt"]
    assert suffixes(cache) == []


TERMINATED = """
import sys
sys.path.insert(0, {root!r})
from mpc import compile_cache
from tests.mpc.test_compile_cache import IPOPT, small_nlp
compile_cache.compiler = lambda: compile_cache.Compiler({gcc!r}, "x", ("-O2",))
compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
"""


@pytest.mark.parametrize("group", [False, True], ids=["process", "process-group"])
def test_a_compile_ended_by_sigterm_removes_its_files_and_ends_by_it(cache, tmp_path, group):
    """A sweep's worker gets SIGTERM from the driver's stop (`kill`, `timeout`; a job scheduler signals the
    whole group, gcc too): its default action ended the process with no finally run, leaving the generated
    source and the object file gcc, running on, wrote after it; only a compile an hour later removed them.
    Now the compile ends first and removes its files, and the process still ends by SIGTERM (-15)."""
    started = tmp_path / "started"
    body = f'for a; do [ "$o" = 1 ] && out=$a; o=; [ "$a" = -o ] && o=1; done; : > {started}; sleep 1'
    slow = fake_compiler(tmp_path, f'{body}; : > "$out"')  # an object file, then a library, each a second
    script = tmp_path / "child.py"
    script.write_text(textwrap.dedent(TERMINATED.format(root=str(ROOT), gcc=slow.path)))
    env = os.environ | {compile_cache.CACHE_ENV: str(cache.parent)}
    child = subprocess.Popen([sys.executable, str(script)], env=env, start_new_session=True)
    for _ in range(2400):  # up to 2 min to reach the compile on a loaded host
        if started.exists() or child.poll() is not None:
            break
        time.sleep(0.05)
    (os.killpg if group else os.kill)(child.pid, signal.SIGTERM)
    assert child.wait(timeout=60) == -signal.SIGTERM
    time.sleep(1.5)  # a gcc that outlived its parent would write its output by now
    assert suffixes(cache) == []


STOPPED = """
import sys
sys.path.insert(0, {root!r})
from mpc import compile_cache
from tests.mpc.test_compile_cache import IPOPT, small_nlp
compile_cache.compiler = lambda: compile_cache.Compiler({gcc!r}, "x", ("-O2",))
try:
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
except KeyboardInterrupt:
    print("KeyboardInterrupt")
"""


def stop_a_slow_compile(cache: Path, tmp_path: Path, signum: int) -> tuple[float, int | None, str]:
    """Send ``signum`` to a child process alone (not its group) while its compile runs gcc (a stand-in that
    sleeps 60 s): seconds from the signal to the child's exit (None: not within 15 s), its exit status and
    what it printed. The stand-in's own process (gcc) is gone by then."""
    child, gcc_pid = at_a_slow_compile(cache, tmp_path, STOPPED)
    try:
        signalled = time.monotonic()
        os.kill(child.pid, signum)
        try:
            status = child.wait(timeout=15)
        except subprocess.TimeoutExpired:
            return time.monotonic() - signalled, None, ""
        stopped = time.monotonic() - signalled
        with pytest.raises(ProcessLookupError):  # reaped, not left running on
            os.kill(int(gcc_pid.read_text()), 0)
        return stopped, status, child.stdout.read() if child.stdout else ""
    finally:
        for group in (child.pid, int(gcc_pid.read_text()) if gcc_pid.exists() else None):
            if group is not None:  # before the change: the child and the sleeping stand-in, still there
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(group, signal.SIGKILL)
        child.wait()


def test_a_compile_ends_on_sigterm_at_once_not_when_gcc_returns(cache, tmp_path):
    """CasADi ran gcc in system(): a SIGTERM's handler ran only once gcc returned, so a worker a sweep's
    stop ended while it compiled lived on up to 8 s (CMPC's NLP), the driver waiting for it. gcc now runs in a
    process group of its own that the compile stops: the process ends by SIGTERM at once, its files gone."""
    seconds, status, _ = stop_a_slow_compile(cache, tmp_path, signal.SIGTERM)
    assert status == -signal.SIGTERM and seconds < 10
    assert suffixes(cache) == []


def test_sigint_to_the_compiling_process_alone_interrupts_it(cache, tmp_path, sigint_as_at_a_terminal):
    """system() ignores SIGINT in its caller while gcc runs: `kill -INT <pid>` of the compiling process
    alone (a terminal's Ctrl-C reaches gcc's process group too) was lost, and the compile ran on. Now it is
    a KeyboardInterrupt at once, gcc stopped and the compile's files gone."""
    seconds, status, out = stop_a_slow_compile(cache, tmp_path, signal.SIGINT)
    assert (status, out.split()) == (0, ["KeyboardInterrupt"]) and seconds < 10
    assert suffixes(cache) == []


THREADED = """
import sys, threading, time
sys.path.insert(0, {root!r})
from mpc import compile_cache
from tests.mpc.test_compile_cache import IPOPT, small_nlp
compile_cache.compiler = lambda: compile_cache.Compiler({gcc!r}, "x", ("-O2",))
def compile():
    try:
        compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    except KeyboardInterrupt:
        print("KeyboardInterrupt in the thread", flush=True)
thread = threading.Thread(target=compile)
thread.start()
while thread.is_alive():  # not join(): one a KeyboardInterrupt cuts short takes the thread for ended (3.11)
    try:
        time.sleep(0.05)
    except KeyboardInterrupt:
        pass
"""


def test_a_ctrl_c_stops_a_compile_off_the_main_thread(cache, tmp_path, sigint_as_at_a_terminal):
    """A compile off the main thread (DMPC's helper threads build their robots' IPOPT) cannot be stopped
    from Python, where signals reach the main thread alone: gcc in a process group of its own was out of a
    terminal's Ctrl-C, ran on after its process had exited and wrote its object file into the cache. There
    it stays in its caller's group: the Ctrl-C ends it, the thread raises KeyboardInterrupt, files gone."""
    child, gcc_pid = at_a_slow_compile(cache, tmp_path, THREADED)
    try:
        os.killpg(child.pid, signal.SIGINT)  # a terminal's Ctrl-C: its foreground process group
        out, _ = child.communicate(timeout=15)
        with pytest.raises(ProcessLookupError):  # ended, not running on
            os.kill(int(gcc_pid.read_text()), 0)
        assert "KeyboardInterrupt in the thread" in out
        assert suffixes(cache) == []
    finally:
        for pid in (child.pid, int(gcc_pid.read_text()) if gcc_pid.exists() else None):
            if pid is not None:  # before the change: the sleeping stand-in, still there
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.kill(pid, signal.SIGKILL)
        child.wait()


@needs_gcc
def test_the_library_is_the_one_casadis_own_compile_makes(cache, monkeypatch, tmp_path):
    """gcc runs here with the arguments CasADi's "shell" plugin gives it: the library is byte for byte the
    one CasADi makes of the same NLP with the same names (jit_name and library name hold the tag)."""
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    (ours,) = cache.glob("*.so")
    tag = ours.name.split(".")[1]
    own = tmp_path / "casadi"
    own.mkdir()
    monkeypatch.chdir(own)  # CasADi writes the source into the working directory
    cc = compile_cache.compiler()
    assert cc is not None
    jit_options = {"compiler": cc.path, "linker": cc.path, "flags": list(cc.flags), "directory": f"{own}/"}
    jit_options |= {"name": ours.stem, "temp_suffix": False, "cleanup": False}
    jit = {"jit": True, "compiler": "shell", "jit_name": f"crowdmpc_jit_{tag}", "jit_temp_suffix": False}
    ca.nlpsol("s", "ipopt", small_nlp(), IPOPT | jit | {"jit_options": jit_options})
    assert (own / ours.name).read_bytes() == ours.read_bytes()


def test_a_compile_leaves_a_programs_own_sigterm_handler(cache, monkeypatch, tmp_path):
    """Only a default action is taken over during a compile, and it is back after: the CLI's
    terminate_as_interrupt (and any program's handler) keeps the signal."""
    failing = fake_compiler(tmp_path, "exit 1")
    monkeypatch.setattr(compile_cache, "compiler", lambda: failing)
    own = lambda signum, frame: None  # noqa: E731
    for handler in (own, signal.SIG_DFL, signal.SIG_IGN):
        saved = signal.signal(signal.SIGTERM, handler)
        try:
            with pytest.raises(compile_cache.CompileCacheError):
                compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
            assert signal.getsignal(signal.SIGTERM) is handler
        finally:
            signal.signal(signal.SIGTERM, saved)
    assert suffixes(cache) == []


@needs_gcc
def test_the_generated_source_is_written_in_the_cache_not_the_working_directory(cache, monkeypatch):
    """CasADi writes <jit_name>.c into the working directory: during the compile that is the cache folder,
    so nothing appears where the user runs (p2), and an unwritable working directory is no failure (p3)."""
    work = Path.cwd()
    seen = []
    nlpsol = ca.nlpsol

    def watched(*args):  # the compile itself: what the working directory holds right after it
        solver = nlpsol(*args)
        seen.append((Path.cwd(), sorted(p.name for p in work.iterdir()), sorted(cache.glob("*.c"))))
        return solver

    monkeypatch.setattr(ca, "nlpsol", watched)
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    ((inside, in_work, sources),) = seen
    assert inside == cache.resolve() and in_work == [] and len(sources) == 1
    assert Path.cwd() == work and list(work.iterdir()) == [] and list(cache.glob("*.c")) == []


@needs_gcc
@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc, unwritable even for root")
def test_an_unwritable_working_directory_does_not_stop_a_compile(cache, monkeypatch):
    monkeypatch.chdir("/proc")
    solver = compile_cache.nlpsol("s", "ipopt", small_nlp(3.0), IPOPT)
    assert solver(x0=0, p=[1, 2], lbg=-1, ubg=1)["x"].shape == (2, 1)
    assert os.getcwd() == "/proc"


@needs_gcc
def test_a_compile_removes_what_killed_compiles_left(cache, tmp_path):
    """A compile killed by SIGKILL left its generated source (~0.5 MB) and more, and no later run removed
    them: now a compile removes those of processes that are gone, and only those."""
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    gone, live, key = int(dead.stdout), os.getpid(), "ab" * 32
    cache.mkdir(parents=True)
    leftovers = [f"crowdmpc_jit_{gone}_0123abcd.c", f"{key}.{gone}_0123abcd.o"]
    leftovers += [f".tmp-{key}.{gone}_0123abcd.casadi", f".tmp-{key}.{gone}_0123abcd.record"]
    kept = [f"crowdmpc_jit_{live}_0123abcd.c", f".tmp-{key}.{live}_0123abcd.casadi"]  # a compile under way
    kept += [f"{key}.{gone}_0123abcd.so", f"notes_{gone}_0123abcd.c"]  # a library; not a name of ours
    for name in leftovers + kept:
        (cache / name).write_text("x")
    for name in leftovers:  # killed more than LEFTOVER_AGE_S ago (a recent one: test_..._another_machine)
        os.utime(cache / name, (time.time() - 2 * LEFTOVER_AGE_S,) * 2)
    outside = tmp_path / "precious.c"
    outside.write_text("keep")
    link = cache / f"crowdmpc_jit_{gone}_4567abcd.c"
    link.symlink_to(outside)
    compile_cache.nlpsol("s", "ipopt", small_nlp(), IPOPT)
    names = {p.name for p in cache.iterdir()}
    assert not names & set(leftovers)
    assert set(kept) | {link.name} <= names and outside.read_text() == "keep"


def test_the_files_of_a_compile_on_another_machine_are_left_alone(tmp_path):
    """Jobs on several nodes sharing $CROWDMPC_CACHE (a cluster's home directory): a compile there has a pid
    no process here has, and every compile here removed its files as a killed compile's while its gcc ran
    (cc1: "crowdmpc_jit_<tag>.c: No such file or directory", its episodes raised). Only old ones go now."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True)
    gone, key = int(dead.stdout), "ab" * 32
    names = [f"crowdmpc_jit_{gone}_0123abcd.c", f"{key}.{gone}_0123abcd.o"]
    names.append(f".tmp-{key}.{gone}_0123abcd.casadi")
    for name in names:
        (tmp_path / name).write_text("x")
    assert remove_dead_leftovers(tmp_path) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)
    os.utime(tmp_path / names[0], (time.time() - 2 * LEFTOVER_AGE_S,) * 2)
    assert remove_dead_leftovers(tmp_path) == 1 and not (tmp_path / names[0]).exists()


def test_a_library_no_entry_names_is_removed_as_a_killed_compiles(tmp_path):
    """A compile SIGKILLed while linking (or before it published its entry) left its library, partial or
    whole, and no cleanup but `cache clear` removed it: no load reads a library no record names. Now it goes
    once an hour old, as the rest of a killed compile does; an entry's library stays, one from before
    records (its manifest alone names it) too."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True)
    gone, live = int(dead.stdout), os.getpid()
    killed, entry, old, other = "ab" * 32, "cd" * 32, "ef" * 32, "12" * 32
    leftovers = [f"{killed}.{gone}_0123abcd.so", f"{entry}.{gone}_4567abcd.so"]  # the latter: not the entry's
    kept = [f"{entry}.{gone}_0123abcd.so", f"{old}.{gone}_0123abcd.so", f"{other}.{live}_0123abcd.so"]
    for name in leftovers + kept:
        (tmp_path / name).write_text("x")
        os.utime(tmp_path / name, (time.time() - 2 * LEFTOVER_AGE_S,) * 2)
    (tmp_path / f"{entry}.casadi").write_text("x")
    (tmp_path / f"{entry}.record").write_text(json.dumps({"library": kept[0]}))
    (tmp_path / f"{old}.casadi").write_text("x")  # stored before records were kept
    assert remove_dead_leftovers(tmp_path) == len(leftovers)
    assert not {p.name for p in tmp_path.iterdir()} & set(leftovers)
    assert all((tmp_path / name).exists() for name in kept)


def test_a_record_nested_past_the_stack_is_no_record(tmp_path):
    """A cache entry's .record edited to nest 100,000 deep ended the run that met it (a load, a discard, the
    cleanup of a killed compile's library) in "RecursionError: maximum recursion depth exceeded while decoding
    a JSON array": the record's reader caught ValueError alone. Now it is no record, as one that is no JSON:
    the entry does not load and its manifest still names its library."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True)
    key = "ab" * 32
    library = tmp_path / f"{key}.{int(dead.stdout)}_0123abcd.so"
    library.write_text("x")
    os.utime(library, (time.time() - 2 * LEFTOVER_AGE_S,) * 2)
    manifest = tmp_path / f"{key}.casadi"
    manifest.write_text("x")
    manifest.with_suffix(".record").write_text("[" * 100_000)
    assert remove_dead_leftovers(tmp_path) == 0 and library.exists()  # an entry from before records: kept
    assert not intact(manifest) and load_solver(manifest) is None
    discard(manifest)
    assert not manifest.exists() and not manifest.with_suffix(".record").exists()


def _fma_flags() -> list[str] | None:
    """The flags that make gcc target a machine with fused multiply-add here: none on aarch64 (its default),
    -mfma on an x86-64 that has it; None where neither holds."""
    import platform

    machine = platform.machine()
    if machine in ("aarch64", "arm64"):
        return []
    cpu = Path("/proc/cpuinfo")
    if (
        machine == "x86_64"
        and cpu.is_file()
        and " fma " in f" {cpu.read_text(encoding='utf-8')} ".replace("\n", " ")
    ):
        return ["-mfma"]
    return None


@needs_gcc
@pytest.mark.skipif(_fma_flags() is None, reason="no fused multiply-add on this machine")
def test_compiled_code_rounds_as_the_interpreter_on_a_machine_with_fused_multiply_add(tmp_path, monkeypatch):
    """gcc -O2 fuses c - a * b into one rounding where the target has FMA (aarch64 by default): the jit's
    numbers then differed from CasADi's interpreter, so --jit changed results, not only the time. With
    a = 1 + 2^-30, b = 1 - 2^-30, c = 1: a * b rounds to 1 and the difference is 0; fused, 2^-60."""
    from mpc.compiler import FLAGS

    monkeypatch.chdir(tmp_path)  # CasADi's jit writes its source into the working directory
    x = ca.SX.sym("x", 3)  # one input: its three loads come first, then the product and the difference
    flags = [*FLAGS, *(_fma_flags() or [])]
    options = {"jit": True, "compiler": "shell", "jit_options": {"flags": flags, "verbose": False}}
    compiled = ca.Function("fused", [x], [x[2] - x[0] * x[1]], options)
    interpreted = ca.Function("fused", [x], [x[2] - x[0] * x[1]])
    values = [1.0 + 2.0**-30, 1.0 - 2.0**-30, 1.0]
    assert float(interpreted(values)) == 0.0
    assert float(compiled(values)) == 0.0
