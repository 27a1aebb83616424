"""Errors a user can cause through the pipelines (bad files, bad options), and the one a sweep stops itself
with (SweepStopped). Printed without a traceback."""


class PipelineError(ValueError):
    """Base class of the user-facing errors raised by `pipelines`."""


class SweepStopped(PipelineError):
    """A sweep that stopped itself part way (its first episodes all raised, its workers kept dying): what it
    recorded stands, and gets its report."""


class EpisodeFailed(PipelineError):
    """A user's error raised inside one episode of ``run_episodes`` (a plugin breaking its contract or
    raising), with the episode that failed named first: ``simulate --seed SEED --episodes 1`` reruns it."""

    def __init__(self, seed: int, scenario: str, error: Exception | str):
        super().__init__(f"episode seed {seed} ({scenario}): {error}")
        self.seed = seed
        self.scenario = scenario
        self.error = str(error)  # its line: the error itself travels as the cause, which pickle drops

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        # Built from its facts, as predictors.errors.DatasetFormatError: a process pool sends a job's
        # exception back pickled, and BaseException's pickle calls the class with the message alone.
        return type(self), (self.seed, self.scenario, self.error)


def interrupt_behind(exc: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C behind ``exc``, if it is one a C extension wrapped: a KeyboardInterrupt raised in Python
    code that CasADi calls back during a solve comes out as ``SystemError('... returned a result with an
    exception set')`` caused by it, which a handler of solver failures would otherwise take for one."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None
