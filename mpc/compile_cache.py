"""Compile once per machine: jit-compiled CasADi solvers cached on disk.

CasADi's ``jit`` (``nlpsol(..., {"jit": True, "compiler": "shell"})``) writes C code for the solver's
functions (objective, gradient, constraint Jacobian, Lagrangian Hessian, ...), compiles it with gcc and loads
the library: 2-8 s of gcc per NLP, which every worker of every sweep used to pay again. Here the first build
of an NLP on a machine compiles it and stores it; every later build, in any process, loads it in milliseconds.

Mechanism (CasADi's own, no generated code of ours): a solver built with ``jit_serialize="link"`` serializes
to a description that names its compiled library instead of carrying source; ``Function.load`` of that
description loads the library (``Importer(library, "dll")``) without generating or compiling anything. An
entry is three files in ``$CROWDMPC_CACHE/compiled`` (default ``~/.cache/crowdmpc/compiled``; which folder,
and whether it can be written and compiled into: mpc/cache_location.py):

* ``<key>.<tag>.so``: the library gcc wrote (``<tag>``: the compiling process and a random suffix, so that
  two processes compiling the same NLP never write the same file);
* ``<key>.record``: the library's name, size and SHA-256, and the SHA-256 of the serialized solver, checked
  before every load: ``Function.load`` maps the library, and one truncated or changed since it was stored
  kills the process (a bus error, no exception); an entry whose record is missing or disagrees (one stored
  before records were kept, too) is unloadable and compiled again;
* ``<key>.casadi``: the serialized solver naming that library, published only once the library and its
  record are complete, by a hard link from a temporary file (``os.link`` never replaces: the first finished
  compile wins, and a reader sees either no entry or a complete one).

gcc runs here (``compiler.run_compiler``), with the arguments CasADi's "shell" plugin gives it, not in
CasADi's ``system()``, which held every signal's handler until gcc returned (a stopped sweep's worker lived
on up to 8 s) and ignored SIGINT in the process (`kill -INT` of it was lost): CasADi's nlpsol generates the
source, runs the shell's no-op ``:`` as compiler and linker and fails to load the library not made yet; gcc
compiles and links it in a process group of its own (on the main thread; off it, in the caller's, which a
terminal's Ctrl-C reaches), which a signal to the process stops at once (on Linux a SIGKILL too); the same
nlpsol again generates the same source (checked) and loads the library, byte for byte the one CasADi's own
compile made. The second code generation costs about 1 % of a compile (3 robots, 7 humans, at load 7:
0.4 s of CMPC's 31 s, 0.1 s of DMPC's 9 s).

While a process compiles an entry it holds ``<key>.lock`` (``flock``), so that the other workers of a sweep
wait for that one compile instead of running their own. Every solver is returned as loaded from its entry,
in the compiling process too: a cold run and a warm one solve with the same object built the same way.

The key is a SHA-256 over what determines the compiled code and the solver: this module's format version,
the cache directory (the entry names its library by absolute path), the CasADi version, the platform, the
compiler (path and ``--version``) and flags, the solver plugin and options, and the serialized NLP
(``Function.serialize`` of ``x, p -> f, g``: the full expression graph). The solver's name is not in it (it
names nothing in the generated code): DMPC's per-robot solvers of one NLP share an entry.

The predictors' CasADi twins are not compiled: measured (7 humans, 3 robots, H = 4), gcc gives
social_lstm_eth's 0.74 ms a call 0.68 ms and vanilla_lstm_eth's 0.27 ms 0.36 ms; their MX graphs are a few
dozen matrix operations, which CasADi's interpreter already runs as compiled loops.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import json
import os
import platform
import secrets
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Final

import casadi as ca

from mpc.cache_entries import (
    NoLocks,
    discard,
    entry_record,
    inside,
    load_solver,
    locked,
    publish,
    remove_dead_leftovers,
)
from mpc.cache_location import CACHE_ENV as CACHE_ENV
from mpc.cache_location import SUBDIR as SUBDIR
from mpc.cache_location import cache_dir as cache_dir
from mpc.cache_location import free_bytes, location_error, writable_dir
from mpc.cache_location import readable_dir as readable_dir
from mpc.compiler import (
    COMPILER,
    Check,
    Compiler,
    compile_command,
    compiler,
    ended_after_cleanup,
    interruptible,
    link_command,
    run_compiler,
)
from mpc.errors import CacheLocationError as CacheLocationError
from mpc.errors import CompileCacheError

# Bump when the layout or the key changes: old entries are then never read (``crowdmpc cache clear``).
FORMAT: Final[int] = 1
# What compiling costs and saves, per NLP, for `crowdmpc sweep --jit auto`, measured by
# benchmarks/compile_cache.py (3 robots, 7 humans, the shared 2-core machine): a cold compile of CMPC's joint
# NLP takes 8.2 s of CPU (COMPILE_S rounds it to 8.0), gcc included (wall 5.1 / 6.7 / 7.8 s at 5 / 7 / 9
# humans with the machine at load 1.4, twice that at load 4), of DMPC's local NLP 2.3 s; a warm load 15-95 ms,
# as long as a build without jit. The jit then saves 0.10-0.11 s of CPU per CMPC episode (0.26 -> 0.15 s; 0.11
# s with social_lstm_eth) and 0.19-0.22 s per DMPC episode (0.51 -> 0.30 s).
COMPILE_S: Final[Mapping[str, float]] = {"joint": 8.0, "local": 2.3}
SAVING_PER_EPISODE_S: Final[Mapping[str, float]] = {"joint": 0.10, "local": 0.19}
# Free space a compile may need: its C source, object, library and entry; the largest entry measured (CMPC,
# 12 robots) is 27 MB, 23 of them its .casadi. Below it, gcc's "No space left" failed every episode.
COMPILE_ROOM_BYTES: Final[int] = 64 * 2**20


def _key(kind: str, options: Mapping, payload: str, cc: Compiler, folder: Path) -> str:
    h = hashlib.sha256()
    header = {
        "format": FORMAT,
        # An entry names its library by absolute path: a cache shared by machines that mount it at different
        # paths keeps one entry per path instead of each replacing the others' as unloadable.
        "directory": str(folder.resolve()),
        "kind": kind,
        "casadi": ca.__version__,
        "platform": [sys.platform, platform.machine()],
        "compiler": [cc.path, cc.version, list(cc.flags)],
        "options": options,
    }
    h.update(json.dumps(header, sort_keys=True, default=repr).encode())
    h.update(b"\0")
    h.update(payload.encode("utf-8", "surrogateescape"))
    return h.hexdigest()


def nlp_key(plugin: str, nlp: Mapping, options: Mapping, cc: Compiler, folder: Path) -> str:
    """The key of ``nlpsol(_, plugin, nlp, options)`` compiled with ``cc`` into ``folder``."""
    names = sorted(nlp)
    oracle = ca.Function("nlp", [nlp["x"], nlp["p"]], [nlp[k] for k in names if k not in ("x", "p")])
    return _key(f"nlpsol:{plugin}:{','.join(names)}", options, oracle.serialize(), cc, folder)


def nlpsol(
    name: str, plugin: str, nlp: Mapping, options: Mapping, *, directory: str | Path | None = None
) -> ca.Function:
    """``casadi.nlpsol(name, plugin, nlp, options)`` compiled with gcc (``compiler.FLAGS``), from the cache
    when it holds this NLP, else compiled now and stored. ``options`` must not set the jit options themselves.

    Raises ``CompileCacheError`` when gcc is not on the PATH, the compile fails, or the cache directory cannot
    be made or compiled into (``CacheLocationError``).
    """
    cc = compiler()
    if cc is None:
        raise CompileCacheError(f"jit needs {COMPILER} on the PATH (CasADi compiles with it)")
    clash = sorted(set(options) & {"jit", "compiler", "jit_options", "jit_name", "jit_serialize"})
    if clash:
        raise ValueError(f"nlpsol options {clash} are set by the compile cache")
    folder = writable_dir(directory)
    key = nlp_key(plugin, nlp, options, cc, folder)
    manifest = folder / f"{key}.casadi"
    solver = load_solver(manifest)
    if solver is not None:
        return solver
    try:
        return _compile_locked(name, plugin, nlp, options, cc, folder, key)
    except NoLocks as exc:
        problem = f"cannot lock {exc.filename} ({exc.strerror}): its file system does not lock files"
        raise location_error(folder, directory, problem, "a folder on a file system that does") from None


def _compile_locked(
    name: str, plugin: str, nlp: Mapping, options: Mapping, cc: Compiler, folder: Path, key: str
) -> ca.Function:
    """The entry ``key`` of ``folder``, compiled now unless another process stored it meanwhile."""
    manifest = folder / f"{key}.casadi"
    # Another process (or thread: flock locks are per open file) compiling this entry is waited for.
    with locked(folder / f"{key}.lock"):
        solver = load_solver(manifest)
        if solver is not None:
            return solver
        discard(manifest)  # unloadable (no record, its library removed or changed): compile again
        remove_dead_leftovers(folder)  # what killed compiles left an hour ago (nothing else removes it)
        # before gcc runs: on a full disk it printed its own errors (a source cut short) above the CLI's line
        _room_for_a_compile(folder)
        try:  # a SIGTERM while it compiles ends the process once the compile's files are gone
            with ended_after_cleanup() as ended:
                _compile_nlpsol(name, plugin, nlp, options, cc, folder, key, ended)
        except CompileCacheError:
            raise
        except RuntimeError as exc:  # CasADi's: code generation or gcc failed
            # the disk filled meanwhile: gcc's "No space left" came as "Compilation failed"
            _room_for_a_compile(folder, exc)
            raise CompileCacheError(
                f"compiling the solver {name!r} into {folder} failed: {_last_line(exc)}"
            ) from exc
        solver = load_solver(manifest)
    if solver is None:
        raise CompileCacheError(f"the compiled solver {manifest} was stored but does not load")
    return solver


def _room_for_a_compile(folder: Path, failure: BaseException | None = None) -> None:
    """OSError ENOSPC naming ``folder`` when its file system has less than COMPILE_ROOM_BYTES free (the CLI's
    one line on a full disk), as the sweep's up-front check refuses --jit on."""
    if free_bytes(folder) < COMPILE_ROOM_BYTES:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(folder)) from failure


def _last_line(exc: BaseException) -> str:
    """The last line of a CasADi error (its first lines are the call stack of CasADi's C++ functions)."""
    lines = [line for line in str(exc).splitlines() if line.strip()]
    return lines[-1].strip() if lines else type(exc).__name__


def _compile_nlpsol(
    name: str, plugin: str, nlp: Mapping, options: Mapping, cc: Compiler, folder: Path, key: str, ended: Check
) -> None:
    tag = f"{os.getpid()}_{secrets.token_hex(4)}"
    library = f"{key}.{tag}"
    # CasADi writes the generated source to <jit_name>.c in the working directory, which is the cache folder
    # while it compiles (inside); the object file and library go to jit_options' directory.
    jit_name = f"crowdmpc_jit_{tag}"
    # resolved: the compile runs inside the folder, where a relative $CROWDMPC_CACHE names another place
    directory = str(folder.resolve()) + os.sep
    source = Path(directory) / f"{jit_name}.c"
    interrupted = Path(directory) / f".tmp-{key}.{tag}.interrupted"
    # gcc runs here (compiler.run_compiler: a signal stops it at once); CasADi's own compile and link, one
    # system() each, run the shell's no-op ":" with the arguments it would have given gcc
    command = interruptible(":", interrupted)
    jit = {
        "jit": True,
        "compiler": "shell",
        "jit_name": jit_name,
        "jit_temp_suffix": False,
        "jit_cleanup": False,  # we remove the source; CasADi would look for it where the process is back in
        "jit_serialize": "link",
        "jit_options": {
            "compiler": command,
            "linker": command,
            "flags": list(cc.flags),
            "directory": directory,
            "name": library,
            "temp_suffix": False,
            "cleanup": False,  # the library is the cache entry: it must outlive this process
            "verbose": False,
        },
    }
    tmp = folder / f".tmp-{key}.{tag}.casadi"
    record = folder / f".tmp-{key}.{tag}.record"
    obj, so = f"{directory}{library}.o", f"{directory}{library}.so"  # the names CasADi gives them
    published = False
    try:
        with inside(folder):
            try:
                casadi_nlpsol = functools.partial(
                    _jit_nlpsol, name, plugin, nlp, dict(options) | jit, interrupted
                )
                code = _generate(casadi_nlpsol, source)
                run_compiler(compile_command(cc, source.name, obj), "Compilation", ended)
                run_compiler(link_command(cc, obj, so), "Linking", ended)
                solver = casadi_nlpsol()  # the same source again, and the library gcc made of it loaded
                if source.read_bytes() != code:
                    raise RuntimeError(f"CasADi generated another {source.name} the second time")
            finally:
                ended()  # a SIGTERM noted in CasADi's calls (ended_after_cleanup): the files go below
        solver.save(str(tmp))
        del solver
        record.write_text(entry_record(tmp, folder / f"{library}.so"), encoding="utf-8")
        # The record before the manifest: a reader that finds the manifest finds its record. Losing the race
        # to another compile (no flock) leaves our record beside its manifest: unloadable, compiled again.
        os.replace(record, folder / f"{key}.record")
        published = publish(tmp, folder / f"{key}.casadi")
    finally:  # a compile's own files, interrupted or not (another process's have another tag)
        for own in (source, interrupted, folder / f"{library}.o", tmp, record):
            own.unlink(missing_ok=True)
        if not published:  # failed, or another process published first (no lock): its library is used
            (folder / f"{library}.so").unlink(missing_ok=True)


def _jit_nlpsol(name: str, plugin: str, nlp: Mapping, options: Mapping, interrupted: Path) -> ca.Function:
    """``casadi.nlpsol`` with the jit options in ``options``; KeyboardInterrupt where the shell CasADi ran
    left the ``interrupted`` marker (compiler.interruptible), a Ctrl-C and no failure."""
    try:
        return ca.nlpsol(name, plugin, dict(nlp), dict(options))
    except RuntimeError:
        if interrupted.exists():
            raise KeyboardInterrupt from None
        raise


def _generate(casadi_nlpsol: Callable[[], ca.Function], source: Path) -> bytes:
    """The C code CasADi generates for the solver, written to ``source``: CasADi's nlpsol with the no-op
    compile writes it, and then fails to load the library no compile made yet (the error expected)."""
    try:
        casadi_nlpsol()
    except RuntimeError:
        if not source.is_file():  # the code generation failed: CasADi's error
            raise
        return source.read_bytes()
    raise RuntimeError(f"CasADi loaded a library for {source.name} before gcc made one")
