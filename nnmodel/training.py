"""The Lightning training loop shared by every network (recipes: :mod:`nnmodel.recipes`).

* :class:`WindowDataModule` cuts normalised records into training windows (``n_init``
  samples of measured history + ``horizon`` simulated samples; ``horizon = 1`` is
  one-step-ahead / series-parallel training, longer horizons are closed-loop training by
  truncated back-propagation through time, i.e. multiple shooting) and serves the
  validation records whole, for a free-run validation error.
* :class:`SimulationTask` is the LightningModule: the loss is the mean-square simulation
  error over each window; the validation metric ``val_loss`` is the free-run NRMSE.
* :func:`fit_core` runs the Trainer: CPU by default, early stopping and best-checkpoint on
  the validation free-run error, learning-rate reduction on plateaus, optional wall-clock
  budget, deterministic seeds; its settings are one :class:`~nnmodel.models.config.TrainingConfig`.

This module knows cores (:class:`~nnmodel.models.core.SequenceCore`) and their normalised
records, never the model classes.
"""
from __future__ import annotations

import contextlib
import datetime
import logging
import math
import os
import signal
import sys
import tempfile
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import torch
import lightning.pytorch as pl
from lightning.pytorch.callbacks import Callback, EarlyStopping, ModelCheckpoint
from torch.utils.data import BatchSampler, DataLoader, Dataset, DistributedSampler, RandomSampler

from physics.errors import InputError

from .batches import free_run_error, pad_batch, split_batch
from .data import window_starts

__all__ = ["WindowDataModule", "SimulationTask", "fit_core", "free_run_error", "execution", "resolve_accelerator",
           "device_name"]


# ====================================================================== data
class _Windows(Dataset):
    """Windows over concatenated normalised records, fetched a whole batch at a time."""

    def __init__(self, seqs, length: int, stride: int):
        us, ys, rhs, starts, off = [], [], [], [], 0
        for s in seqs:
            st = window_starts(len(s), length, stride)
            starts.append(st + off)
            us.append(s.u)
            ys.append(s.y)
            if s.rh is not None:
                rhs.append(s.rh)
            off += len(s)
        # u: (N,) or (N, channels); rh likewise (channels last)
        self.u = torch.as_tensor(np.concatenate(us), dtype=torch.float32) if us else torch.zeros(0)
        self.y = torch.as_tensor(np.concatenate(ys), dtype=torch.float32) if ys else torch.zeros(0)
        self.rh = torch.as_tensor(np.concatenate(rhs), dtype=torch.float32) if rhs else None
        self.starts = torch.as_tensor(np.concatenate(starts) if starts else np.zeros(0, np.int64))
        self.offsets = torch.arange(length)

    def __len__(self):
        return int(self.starts.numel())

    def __getitem__(self, idx):
        idx = self.starts[torch.as_tensor(idx)][:, None] + self.offsets[None, :]
        return {"u": self.u[idx], "y": self.y[idx],
                "rh": None if self.rh is None else self.rh[idx]}


def _collate_none(batch):
    return batch


#: Fewest optimizer steps per epoch: the batch shrinks on short records (a recipe's batch of
#: 256 windows would otherwise give one step per epoch and early stopping after a few steps).
MIN_STEPS_PER_EPOCH = 8

#: How training runs (not what is trained): processes/devices and Lightning strategy.  Set
#: with :func:`execution` (``eap train-compare --devices 2 --strategy ddp_spawn``).
EXECUTION = {"devices": 1, "strategy": "auto"}


@contextlib.contextmanager
def execution(devices: int = 1, strategy: str = "auto"):
    """Train with ``devices`` processes/devices and a Lightning ``strategy`` (e.g. ``ddp_spawn``
    on CPUs with the gloo backend, ``ddp`` on GPUs) inside the block."""
    from physics.limits import check_count
    from physics.execution.parallel import cores
    gpus = torch.cuda.device_count() if torch.cuda.is_available() else 0
    check_count(devices, 1, gpus or cores(), "--devices",
                f"the {'GPUs' if gpus else 'CPU cores'} of this machine; one training process each")
    old = dict(EXECUTION)
    EXECUTION.update(devices=devices, strategy=strategy)
    try:
        yield
    finally:
        EXECUTION.update(old)


#: ``--accelerator`` choices of ``eap train-compare``
ACCELERATORS = ("auto", "cpu", "gpu")


def resolve_accelerator(choice: str) -> str:
    """The Lightning accelerator of ``--accelerator CHOICE``: ``auto`` is ``gpu`` when torch
    sees a CUDA device and ``cpu`` otherwise; ``gpu`` without one is an error."""
    if choice not in ACCELERATORS:
        raise InputError(f"--accelerator {choice!r}: expected one of {', '.join(ACCELERATORS)}")
    has_gpu = bool(torch.cuda.is_available())
    if choice == "gpu" and not has_gpu:
        raise InputError("--accelerator gpu: torch sees no GPU (CUDA) on this machine; use --accelerator cpu, or "
                         "auto to use a GPU only where there is one")
    return "gpu" if choice == "gpu" or (choice == "auto" and has_gpu) else "cpu"


def device_name(accelerator: str) -> str:
    """What a network trained on: ``cpu``, or ``gpu (NAME)``."""
    if accelerator in ("gpu", "cuda") and torch.cuda.is_available():
        return f"gpu ({torch.cuda.get_device_name(0)})"
    return "cpu" if accelerator in ("cpu", "gpu", "cuda") else str(accelerator)


class WindowDataModule(pl.LightningDataModule):
    """Training windows and whole validation records (normalised)."""

    def __init__(self, train_seqs, val_seqs, n_init: int, horizon: int, stride: int,
                 batch_size: int, seed: int = 0):
        super().__init__()
        self.train_seqs, self.val_seqs = list(train_seqs), list(val_seqs or [])
        self.n_init, self.horizon, self.stride = int(n_init), int(horizon), int(stride)
        self.batch_size, self.seed = int(batch_size), int(seed)
        self.train_set = None

    def setup(self, stage=None):
        if self.train_set is None:
            self.train_set = _Windows(self.train_seqs, self.n_init + self.horizon, self.stride)
            if len(self.train_set) == 0:
                raise InputError(f"every training record is shorter than one training window "
                                 f"({self.n_init + self.horizon} samples)")

    def train_dataloader(self):
        trainer = getattr(self, "trainer", None)
        world = int(getattr(trainer, "world_size", 1) or 1)
        if world > 1:   # several processes (DDP): each draws its own shard of the windows
            base = DistributedSampler(self.train_set, num_replicas=world, rank=int(trainer.global_rank),
                                      shuffle=True, seed=self.seed)
            base.set_epoch(int(trainer.current_epoch))
        else:
            base = RandomSampler(self.train_set, generator=torch.Generator().manual_seed(self.seed))
        sampler = BatchSampler(base, self.batch_size, drop_last=False)
        return DataLoader(self.train_set, sampler=sampler, batch_size=None, collate_fn=_collate_none)

    def val_dataloader(self):
        if not self.val_seqs:
            return []
        return DataLoader([pad_batch(self.val_seqs, self.n_init)], batch_size=None,
                          collate_fn=_collate_none)


# ====================================================================== module
class SimulationTask(pl.LightningModule):
    """Simulation-error training of a :class:`nnmodel.models.core.SequenceCore`."""

    def __init__(self, core, lr: float = 1e-3, weight_decay: float = 0.0, lr_patience: int = 10,
                 lr_factor: float = 0.3, monitor: str = "val_loss", min_lr: float = 1e-6):
        super().__init__()
        self.core = core
        self.lr, self.weight_decay = lr, weight_decay
        self.lr_patience, self.lr_factor, self.min_lr = lr_patience, lr_factor, min_lr
        self.monitor = monitor
        self._sse = self._cnt = 0.0

    def training_step(self, batch, batch_idx):
        k = self.core.n_init
        hist, u, y, rh = split_batch(batch, k)
        y_hat = self.core.simulate(self.core.init_state(*hist), u, rh)
        loss = torch.mean((y_hat - y) ** 2)
        self.log("train_loss", loss, on_step=False, on_epoch=True, prog_bar=True,
                 batch_size=u.shape[0], sync_dist=self._distributed())
        return loss

    def on_validation_epoch_start(self):
        self._sse, self._cnt = 0.0, 0.0

    def validation_step(self, batch, batch_idx):
        k = self.core.n_init
        hist, u, y, rh = split_batch(batch, k)
        mask = batch["mask"][:, k:]
        y_hat = self.core.simulate(self.core.init_state(*hist), u, rh)
        err = torch.nan_to_num((y_hat - y) ** 2, nan=1e12, posinf=1e12) * mask
        self._sse += float(err.sum())
        self._cnt += float(mask.sum())

    def on_validation_epoch_end(self):
        if self._cnt:
            v = math.sqrt(self._sse / self._cnt)
            self.log("val_loss", min(v, 1e6), prog_bar=True, sync_dist=self._distributed())

    def _distributed(self) -> bool:
        """True with several processes: epoch metrics are then averaged over them."""
        return int(getattr(self.trainer, "world_size", 1) or 1) > 1

    def configure_optimizers(self):
        opt = torch.optim.Adam(self.core.parameters(), lr=self.lr, weight_decay=self.weight_decay)
        sched = torch.optim.lr_scheduler.ReduceLROnPlateau(
            opt, mode="min", factor=self.lr_factor, patience=self.lr_patience, min_lr=self.min_lr)
        return {"optimizer": opt,
                "lr_scheduler": {"scheduler": sched, "monitor": self.monitor, "interval": "epoch"}}


class _History(Callback):
    def __init__(self):
        self.rows = []

    def on_train_epoch_end(self, trainer, module):
        m = trainer.callback_metrics
        row = {"epoch": int(trainer.current_epoch),
               "lr": float(trainer.optimizers[0].param_groups[0]["lr"])}
        for key in ("train_loss", "val_loss"):
            if key in m:
                row[key] = float(m[key])
        self.rows.append(row)


class _LineProgress(Callback):
    """Progress for a non-terminal (log files, CI): one line per epoch, at most one every
    :data:`LOG_EVERY_S` seconds, instead of Lightning's carriage-return bar."""

    def __init__(self):
        self._last = -math.inf

    def on_train_epoch_end(self, trainer, module):
        now = time.monotonic()
        if now - self._last < LOG_EVERY_S and trainer.current_epoch + 1 < trainer.max_epochs:
            return
        self._last = now
        m = trainer.callback_metrics
        losses = ", ".join(f"{k} {float(m[k]):.4g} ({what(float(m[k]))})" for k, what in (
            ("train_loss", lambda x: f"mean square on windows, √ = {math.sqrt(x):.3g}"),
            ("val_loss", lambda x: "free-run RMS")) if k in m)
        print(f"  epoch {trainer.current_epoch + 1}/{trainer.max_epochs}: {losses}", file=sys.stderr, flush=True)


#: Seconds between progress lines when stderr is not a terminal.
LOG_EVERY_S = 10.0


@contextlib.contextmanager
def _quiet_lightning():
    """Silence Lightning's start-up chatter (device summary, seeds, worker hints)."""
    names = ["lightning.pytorch", "lightning.pytorch.utilities.rank_zero",
             "lightning.pytorch.accelerators.cuda", "lightning.fabric"]
    old = {n: logging.getLogger(n).level for n in names}
    for n in names:
        logging.getLogger(n).setLevel(logging.WARNING)
    with warnings.catch_warnings():
        for pat in (".*does not have many workers.*", ".*smaller than the logging interval.*",
                    ".*Checkpoint directory.*exists and is not empty.*",
                    ".*GPU available but not used.*", ".*`isinstance\\(treespec, LeafSpec\\)`.*"):
            warnings.filterwarnings("ignore", message=pat)
        try:
            yield
        finally:
            for n, lvl in old.items():
                logging.getLogger(n).setLevel(lvl)


def _fit_interruptible(trainer, task, dm) -> None:
    """``trainer.fit`` that lets Ctrl-C through: Lightning answers a KeyboardInterrupt with a
    graceful shutdown, ``sys.exit(1)`` and SIGINT ignored from then on; here the handler is
    restored and the KeyboardInterrupt raised again, so the command ends as on any other
    Ctrl-C (exit 130, nothing that looks complete)."""
    handler = signal.getsignal(signal.SIGINT)
    try:
        trainer.fit(task, datamodule=dm)
    except SystemExit as exc:
        if isinstance(exc.__context__, KeyboardInterrupt):
            raise KeyboardInterrupt from None
        raise
    finally:
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, handler)


def batch_message(n_windows: int, asked: int, used: int) -> str:
    """What lowering the batch size on short records does, in numbers that hold."""
    steps = math.ceil(n_windows / used)
    why = (f"so that an epoch has at least {MIN_STEPS_PER_EPOCH} optimizer steps ({steps})"
           if steps >= MIN_STEPS_PER_EPOCH else
           f"one window per optimizer step, {steps} steps per epoch ({MIN_STEPS_PER_EPOCH} would need "
           f"{MIN_STEPS_PER_EPOCH} windows)")
    return f"{n_windows} training window{'' if n_windows == 1 else 's'}: batch size {asked} lowered to {used}, {why}"


def fit_core(core, train_seqs, val_seqs, config) -> tuple[list[dict], dict]:
    """Train ``core`` in place with Lightning as ``config`` (a
    :class:`~nnmodel.models.config.TrainingConfig`) says; restores the best (validation
    free-run) weights at the end and returns (the per-epoch history, the budget used: epochs
    run and whether the wall-clock guard ``max_time`` ended the training)."""
    c = config
    seed, batch_size, max_epochs, max_time, patience = c.seed, c.batch_size, c.max_epochs, c.max_time, c.patience
    pl.seed_everything(seed, workers=True, verbose=False)
    monitor = "val_loss" if val_seqs else "train_loss"
    dm = WindowDataModule(train_seqs, val_seqs, core.n_init, c.horizon, c.stride, batch_size, seed)
    dm.setup()
    n_windows = len(dm.train_set)
    if n_windows < MIN_STEPS_PER_EPOCH * batch_size:   # short records: keep several optimizer steps per epoch
        dm.batch_size = max(1, n_windows // MIN_STEPS_PER_EPOCH)
        warnings.warn(batch_message(n_windows, batch_size, dm.batch_size), UserWarning, stacklevel=3)
    task = SimulationTask(core, lr=c.lr, weight_decay=c.weight_decay, monitor=monitor,
                          lr_patience=max(2, patience // 3))
    hist = _History()
    # the starting point (least-squares initialisation) competes with the trained epochs
    init_state = {k: v.detach().clone() for k, v in core.state_dict().items()}
    init_val = free_run_error(core, val_seqs) if val_seqs else None
    if init_val is not None:
        hist.rows.append({"epoch": -1, "val_loss": init_val})
    with contextlib.ExitStack() as stack:
        ckdir = c.checkpoint_dir or stack.enter_context(tempfile.TemporaryDirectory(prefix="eap-ckpt-"))
        Path(ckdir).mkdir(parents=True, exist_ok=True)
        ckpt = ModelCheckpoint(dirpath=ckdir, filename="best", monitor=monitor, mode="min",
                               save_top_k=1, save_weights_only=True, enable_version_counter=False)
        stop = EarlyStopping(monitor=monitor, mode="min", patience=patience, check_finite=False)
        tty = sys.stderr.isatty()
        progress_bar = c.progress_bar
        with _quiet_lightning():
            devices, strategy = EXECUTION["devices"], EXECUTION["strategy"]
            trainer = pl.Trainer(
                accelerator=c.accelerator, devices=devices, strategy=strategy, max_epochs=max_epochs,
                deterministic=True if c.accelerator not in ("cpu", "auto") else None,   # same seed, same weights
                use_distributed_sampler=False, reload_dataloaders_every_n_epochs=1 if devices > 1 else 0,
                max_time=None if max_time is None else datetime.timedelta(seconds=float(max_time)),
                callbacks=[ckpt, stop, hist] + ([_LineProgress()] if progress_bar and not tty else []),
                enable_progress_bar=progress_bar and tty, logger=False,
                enable_model_summary=False, num_sanity_val_steps=0, log_every_n_steps=1,
                gradient_clip_val=c.grad_clip, default_root_dir=ckdir)
            t_fit = time.monotonic()
            _fit_interruptible(trainer, task, dm)
            elapsed = time.monotonic() - t_fit
        task.cpu()   # inference and the bundle are on the CPU, whatever trained it
        # with spawned processes (DDP) the callback's state stays in them: the file is the record
        best = ckpt.best_model_path or str(Path(ckdir) / "best.ckpt")
        if best and os.path.exists(best):
            # our own checkpoint, still read without unpickling arbitrary objects
            state = torch.load(best, map_location="cpu", weights_only=True)["state_dict"]
            task.load_state_dict(state)
        best_score = None if ckpt.best_model_score is None else float(ckpt.best_model_score)
        if best_score is None and val_seqs and os.path.exists(best):
            best_score = free_run_error(core, val_seqs)
        if init_val is not None and (best_score is None or not init_val > best_score):
            core.load_state_dict(init_state)  # training did not beat the initialisation
    core.eval()
    # the wall-clock limit is a guard: record when it, not the epoch budget or early
    # stopping, ended the training (the result then depends on the machine's speed)
    epochs = int(trainer.current_epoch)
    fired = bool(max_time is not None and elapsed >= float(max_time) and not stop.stopped_epoch
                 and epochs < max_epochs)
    summary = {"epochs_run": epochs, "time_guard_fired": fired, "max_epochs": int(max_epochs),
               "max_time_s": max_time, "batch_size": int(dm.batch_size), "training_windows": int(n_windows),
               "device": device_name(c.accelerator)}
    if fired:
        warnings.warn(f"training stopped by the wall-clock guard max_time={max_time:g} s after {epochs} of "
                      f"{max_epochs} epochs: the result depends on this machine's speed; raise max_time or "
                      "lower max_epochs for a reproducible budget", RuntimeWarning, stacklevel=2)
    return hist.rows, summary
