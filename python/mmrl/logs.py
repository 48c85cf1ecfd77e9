"""Training metrics: ``metrics.csv`` (plus TensorBoard when installed) and the progress bar.

CSV columns are ``MetricsLogger.BASE_COLUMNS`` followed by any extra columns the first
logged row carries (e.g. a curriculum's). On resume the file is appended to, after dropping
rows logged past the checkpoint resumed from (and a torn last line); a fresh run starts a new
file. TensorBoard is optional: without the
``tensorboard`` package, only the CSV is written (with one warning per process).
"""
from __future__ import annotations

import csv
import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

from .io import atomic_open

__all__ = ["MetricsLogger", "ProgressBar", "progress_settings"]

_warned_no_tensorboard = False


def _summary_writer(out_dir: Path) -> Any:
    """A TensorBoard SummaryWriter, or None (with one warning) if tensorboard is missing."""
    global _warned_no_tensorboard
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError as error:
        if not _warned_no_tensorboard:
            _warned_no_tensorboard = True
            warnings.warn(f"TensorBoard logging is off: the tensorboard package is not importable ({error}); "
                          f"metrics go to metrics.csv only. Install tensorboard to get event files.",
                          stacklevel=3)
        return None
    return SummaryWriter(str(out_dir))


def _row_step(row: list, num_columns: int) -> float:
    """The step of a metrics row; +inf (dropped) for a row that is not whole."""
    if len(row) != num_columns:
        return float("inf")
    try:
        return float(row[0])
    except ValueError:
        return float("inf")


class MetricsLogger:
    """metrics.csv (appended on resume) plus an optional TensorBoard writer."""

    BASE_COLUMNS = ("step", "wall_s", "iteration", "episode_return", "episode_length", "success_rate",
                    "episodes", "sps", "learning_rate", "policy_loss", "value_loss", "entropy", "approx_kl",
                    "clipfrac", "explained_variance", "env_us", "act_us", "update_us")
    LOSS_KEYS = ("policy_loss", "value_loss", "entropy", "approx_kl", "clipfrac", "explained_variance")

    def __init__(self, out_dir: str | Path, resume_step: Optional[int], tensorboard: bool):
        out_dir = Path(out_dir)
        self.path = out_dir / "metrics.csv"
        self.columns: Optional[list[str]] = None
        # A fresh run (resume_step None) starts a new file: rows left by an earlier run that was
        # killed before its first checkpoint must not stay in front of this run's rows.
        self._drop_rows_after(0 if resume_step is None else resume_step)
        self.file = open(self.path, "a", newline="")
        self.writer: Optional[csv.DictWriter] = None
        if self.columns is not None:
            self.writer = csv.DictWriter(self.file, self.columns, extrasaction="ignore")
        self.tb = _summary_writer(out_dir) if tensorboard else None

    def _drop_rows_after(self, resume_step: int) -> None:
        """Drop rows logged after the checkpoint we resume from, and a last line without its
        newline (torn by a kill or a power loss while it was written); keep the header's columns.
        With no data row left the file is removed, so the next row writes the header again."""
        if not self.path.exists():
            return
        with open(self.path, newline="") as file:
            text = file.read()
        lines = text.splitlines(keepends=True)
        torn = bool(lines) and not lines[-1].endswith("\n")
        rows = list(csv.reader(lines[:-1] if torn else lines))
        if not rows:
            self.path.unlink()
            return
        header = rows[0]
        kept = [header] + [r for r in rows[1:] if _row_step(r, len(header)) <= resume_step]
        if len(kept) == 1:
            self.path.unlink()
            return
        self.columns = header
        if len(kept) != len(rows) or torn:
            with atomic_open(self.path, "w", newline="") as file:
                csv.writer(file).writerows(kept)

    def write(self, row: dict) -> None:
        if self.writer is None:
            extra = [k for k in row if k not in self.BASE_COLUMNS]
            self.columns = list(self.BASE_COLUMNS) + extra
            self.writer = csv.DictWriter(self.file, self.columns, extrasaction="ignore")
            self.writer.writeheader()
        self.writer.writerow({k: row.get(k, "") for k in self.columns})
        self.file.flush()
        if self.tb is not None:
            step = int(row["step"])
            for key, value in row.items():
                if key in ("step", "iteration") or not np.isfinite(value):
                    continue
                group = "time" if key.endswith("_us") else "losses" if key in self.LOSS_KEYS else "charts"
                name = {"sps": "SPS"}.get(key, key)
                self.tb.add_scalar(f"{group}/{name}", value, step)

    def close(self) -> None:
        self.file.close()
        if self.tb is not None:
            self.tb.close()


# ----------------------------------------------------------------------------- progress bar

def progress_settings(total_steps: int, max_seconds: Optional[float], global_step: int = 0,
                      wall_s: float = 0.0) -> dict:
    """tqdm arguments for the training bar.

    With a time budget (``max_seconds`` set) the bar counts seconds of training wall time
    out of the budget, so its ETA is the budget's remainder; a step total would be the
    placeholder ``total_steps`` (10**12 for ``mmrl train --seconds``). Otherwise it counts
    env steps out of ``total_steps``. ``global_step``/``wall_s`` are where a resumed run starts.
    """
    if max_seconds is not None:
        budget = float(max_seconds)
        return {"total": budget, "initial": min(float(wall_s), budget), "unit": "s",
                "bar_format": "{l_bar}{bar}| {n:.0f}/{total:.0f} s [{elapsed}<{remaining}{postfix}]"}
    return {"total": int(total_steps), "initial": min(int(global_step), int(total_steps)), "unit": "step"}


class ProgressBar:
    """The tqdm bar of a training run; ``update`` after each iteration (see ``progress_settings``)."""

    def __init__(self, total_steps: int, max_seconds: Optional[float], global_step: int, wall_s: float,
                 **tqdm_kwargs: Any):
        from tqdm.auto import tqdm

        settings = progress_settings(total_steps, max_seconds, global_step, wall_s)
        self.by_seconds = settings["unit"] == "s"
        self.limit = settings["total"]
        self.bar = tqdm(**settings, dynamic_ncols=True, **tqdm_kwargs)

    def update(self, global_step: int, wall_s: float, row: dict) -> None:
        done = wall_s if self.by_seconds else global_step
        self.bar.update(min(done, self.limit) - self.bar.n)
        postfix = {"step": f"{global_step:,}"} if self.by_seconds else {}
        postfix.update(sps=f"{row['sps']:.0f}", ret=f"{row['episode_return']:.1f}",
                       success=f"{row['success_rate']:.2f}")
        self.bar.set_postfix(postfix, refresh=False)

    def close(self) -> None:
        self.bar.close()
