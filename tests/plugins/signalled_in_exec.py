"""A plugin module that meets a stop signal inside code run from a string, as the methods dataclasses and
namedtuples generate are while torch, CasADi or scipy is imported. The signal is named by
$CROWDMPC_TEST_SIGNAL (default SIGTERM)."""

exec(
    "import os, signal, time\n"
    "os.kill(os.getpid(), getattr(signal, os.environ.get('CROWDMPC_TEST_SIGNAL', 'SIGTERM')))\n"
    "time.sleep(5)\n"
)
