"""``crowdmpc cache``: the persistent compile cache of the jit-compiled MPC solvers (mpc/compile_cache.py)."""

from __future__ import annotations

import argparse
import json

from pipelines.commands import check_writable, examples, write_output
from pipelines.commands.standard_output import is_stdout, json_path, shown
from pipelines.errors import PipelineError

EPILOG = """examples:
  crowdmpc cache info
  crowdmpc cache info --json
  crowdmpc cache info --json runs/cache.json
  crowdmpc cache clear

With jit (`crowdmpc sweep --jit auto|on`), each NLP is compiled with gcc once per machine and stored in
$CROWDMPC_CACHE/compiled (else $XDG_CACHE_HOME/crowdmpc/compiled, by default ~/.cache/crowdmpc/compiled): a
serialized solver (<key>.casadi) and its library (<key>.<tag>.so). Every later build, in any worker of any
run, loads it in milliseconds. The key hashes the NLP's expression graph, the solver and its options, the
CasADi version and the compiler with its flags, so an entry is never used for anything else; a CasADi or gcc
upgrade starts new entries (clear the old ones). `clear` removes the cache's own files only, never a symlink
or what it points to; a run that already loaded an entry keeps using it, and an entry another process is
compiling now is left to it.
"""


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "cache",
        help="the compile cache of the jit-compiled MPC solvers (info, clear)",
        description="Show or clear the persistent cache of compiled MPC solvers.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = parser.add_subparsers(dest="cache_command", metavar="ACTION", required=True)
    info = actions.add_parser(
        "info",
        help="directory, entries, size, CasADi version and compiler",
        **examples("crowdmpc cache info", "crowdmpc cache info --json"),
    )
    info.add_argument(
        "--json",
        nargs="?",
        const="-",
        type=json_path,
        metavar="FILE",
        help="the same as one JSON object, on standard output (no FILE, or -) or into FILE",
    )
    actions.add_parser(
        "clear",
        help="remove every compiled entry (the next jit build compiles again)",
        **examples("crowdmpc cache clear"),
    )
    parser.set_defaults(func=run)


def _size(n: int) -> str:
    return f"{n} B" if n < 1024 else f"{n / 1024:.1f} KiB" if n < 1024**2 else f"{n / 1024**2:.1f} MiB"


def run(args: argparse.Namespace) -> int:
    from mpc import cache_admin
    from mpc.cache_location import cache_dir
    from mpc.errors import CompileCacheError

    if args.cache_command == "info":
        stats = cache_admin.info()
        if args.json is not None:
            check_writable(args.json, "--json", json_only=True)
            fields = {**stats.__dict__, "directory": str(stats.directory)}
            write_output(args.json, json.dumps(fields, indent=2) + "\n", "--json")
            if not is_stdout(args.json):
                print(f"wrote {shown(args.json)}")
            return 0
        where = str(stats.directory) + ("" if stats.exists else " (not created yet)")
        print(f"directory: {where}")
        print(f"entries:   {stats.entries} ({stats.files} files, {_size(stats.size_bytes)})")
        print(f"casadi:    {stats.casadi_version}")
        print(f"compiler:  {stats.compiler}")
        return 0
    try:
        removed, freed, busy = cache_admin.clear()
    except CompileCacheError as exc:
        raise PipelineError(str(exc)) from exc
    left = (
        f"; left {busy} entr{'y' if busy == 1 else 'ies'} another process is compiling now (clear again once "
        "it is done)"
        if busy
        else ""
    )
    files = "file" if removed == 1 else "files"
    print(f"removed {removed} {files} ({_size(freed)}) from {cache_dir()}{left}")
    return 0
