"""A plugin module whose import meets a stop signal: `kill` (or `timeout`, a closed terminal) while crowdmpc
starts. The signal is named by $CROWDMPC_TEST_SIGNAL (default SIGTERM)."""

import os
import signal
import time

os.kill(os.getpid(), getattr(signal, os.environ.get("CROWDMPC_TEST_SIGNAL", "SIGTERM")))
time.sleep(5)  # the handler runs at the next bytecode; the default action has ended the process before
