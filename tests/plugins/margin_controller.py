"""A plugin as a user writes one (docs/extending.md section 6): CMPC with its margins, wrapped; its
constructor looks the margins up through MPCController as any wrapper of it does."""

from pipelines.loop.mpc import MPCController


class MarginMPC:
    name = "margin_mpc"
    uses_predictor = True
    compiles = True

    def __init__(self, spec, env_config, *, jit=False):
        self._mpc = MPCController(spec, False, env_config=env_config, jit=jit)
        self.predictor = self._mpc.predictor

    def reset(self, obs):
        self._mpc.reset(obs)

    def act(self, obs):
        return self._mpc.act(obs)

    def describe(self):
        return self._mpc.describe()

    def close(self):
        self._mpc.close()
