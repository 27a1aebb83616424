"""The checkpoint callback of ``crowdmpc train`` (imported with Lightning, when a run starts)."""

from __future__ import annotations

from typing import Any

from lightning.pytorch.callbacks import ModelCheckpoint

from pipelines.commands.train_resume import relocated


class RunCheckpoint(ModelCheckpoint):
    """Lightning's ModelCheckpoint, resuming a run whose folder was moved or copied as one left in place (the
    paths of its best and last checkpoints are read in its folder now, not in the one they were written in),
    and writing last.ckpt at every epoch's end."""

    @property
    def state_key(self) -> str:
        # ModelCheckpoint's own key: the last.ckpt of a run started before this class still resumes its state
        return super().state_key.replace(type(self).__qualname__, ModelCheckpoint.__qualname__, 1)

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        super().load_state_dict(relocated(state_dict, str(self.dirpath)))

    # Lightning (2.6) writes last.ckpt only at an epoch that is a new best: a run stopped after a worse epoch
    # resumed from an earlier one, and a run that ended said it had trained fewer epochs than it had (its
    # --resume trained the same epochs again). Every epoch now writes last.ckpt, where Lightning saves.
    def on_train_epoch_end(self, trainer: Any, pl_module: Any) -> None:
        super().on_train_epoch_end(trainer, pl_module)
        if self._should_save_on_train_epoch_end(trainer):
            self._save_last_unless_saved(trainer)

    def on_validation_end(self, trainer: Any, pl_module: Any) -> None:
        super().on_validation_end(trainer, pl_module)
        if not self._should_save_on_train_epoch_end(trainer):
            self._save_last_unless_saved(trainer)

    def _save_last_unless_saved(self, trainer: Any) -> None:
        # skipped too when this step is saved already: a new best writes last.ckpt with it
        if not self._should_skip_saving_checkpoint(trainer):
            self._save_last_checkpoint(trainer, self._monitor_candidates(trainer))
