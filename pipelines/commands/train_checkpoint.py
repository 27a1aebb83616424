"""The checkpoint callback of ``crowdmpc train`` (imported with Lightning, when a run starts)."""

from __future__ import annotations

from typing import Any

from lightning.pytorch.callbacks import ModelCheckpoint

from pipelines.commands.train_resume import relocated


class RunCheckpoint(ModelCheckpoint):
    """Lightning's ModelCheckpoint, resuming a run whose folder was moved or copied as one left in place: the
    paths of its best and last checkpoints are read in its folder now, not in the one they were written in."""

    @property
    def state_key(self) -> str:
        # ModelCheckpoint's own key: the last.ckpt of a run started before this class still resumes its state
        return super().state_key.replace(type(self).__qualname__, ModelCheckpoint.__qualname__, 1)

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        super().load_state_dict(relocated(state_dict, str(self.dirpath)))
