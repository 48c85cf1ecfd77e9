"""Learning-curve and trajectory plots of a training run (the paper's Figure 4), as PNG."""
from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import List, Optional

import numpy as np


def read_metrics(run: Path) -> dict:
    """metrics.csv as a dict of float arrays (missing values are NaN)."""
    path = Path(run) / "metrics.csv"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no metrics in this run directory")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path}: no rows yet")
    out = {}
    for k in rows[0]:
        vals = []
        for r in rows:
            try:
                vals.append(float(r[k]))
            except (TypeError, ValueError):
                vals.append(math.nan)
        out[k] = np.array(vals)
    return out


def snapshot_paths(run: Path) -> List[tuple]:
    """(step, path) of RUN/snapshot_<step>.pt files, sorted by step."""
    snaps = []
    for p in Path(run).glob("snapshot_*.pt"):
        m = re.fullmatch(r"snapshot_(\d+)\.pt", p.name)
        if m:
            snaps.append((int(m.group(1)), p))
    return sorted(snaps)


def rollout_to_targets(policy, db, targets, seed: int = 0, max_steps: int = 100, config=None, task=None):
    """Drive one character from the same start toward each target in turn (one episode per
    target, each from the seeded start, on the fast path). Returns a list of (K, 2) root
    paths (x, z), one point per played frame."""
    from ..rollout import FullPath, policy_actions
    from ..tasks import get_task

    task = task or get_task("plane")
    config = (config or task.default_config()).replace(max_steps=max_steps)
    paths = []
    for tx, tz in targets:
        run = FullPath(task, db, config=config, seed=seed, fast=True, record=False)
        run.set_target(tx, tz)
        path = [run.character.root[:2]]
        while True:
            out = run.step(policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1))
            path.extend(map(tuple, out["res"].roots[:out["step_frames"], :2]))
            if out["done"]:
                break
        paths.append(np.array(path))
    return paths


def plot_run(run: Path, out_dir: Optional[Path] = None, num_targets: int = 4, seed: int = 0) -> List[Path]:
    """Write learning.png (return, length and success against steps and wall time) and, when the
    run has snapshots, trajectories.png (top-down paths of each snapshot toward the same targets)."""
    from ..errors import require_extra

    matplotlib = require_extra("matplotlib", "viz", "mmrl plot")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = Path(run)
    out_dir = Path(out_dir) if out_dir else run / "plots"
    out_dir.mkdir(parents=True, exist_ok=True)
    m = read_metrics(run)
    written = []
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), constrained_layout=True)
    series = [("episode_return", "episode return"), ("episode_length", "episode length (steps)"),
              ("success_rate", "success rate")]
    snaps = snapshot_paths(run)
    for row, (xkey, xlabel) in enumerate([("step", "env steps"), ("wall_s", "training wall time (s)")]):
        for col, (key, label) in enumerate(series):
            ax = axes[row, col]
            if key in m:
                ax.plot(m[xkey], m[key], lw=1.2)
            ax.set_xlabel(xlabel)
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
            for k, (step, _) in enumerate(snaps):
                x = step if xkey == "step" else np.interp(step, m["step"], m["wall_s"])
                ax.axvline(x, ls="--", lw=0.8, color=f"C{k + 1}")
    fig.suptitle(f"{run.name}: learning curves")
    path = out_dir / "learning.png"
    _save(fig, path)
    plt.close(fig)
    written.append(path)

    if snaps:
        from ..rl import ppo
        from ..runs import RunDir

        rundir = RunDir(run)
        if rundir.task is None or rundir.task.scene is None:  # paths on an empty plane
            db = rundir.database()
            rng = np.random.default_rng(seed)
            angles = np.linspace(0, 2 * np.pi, num_targets, endpoint=False) + rng.uniform(0, np.pi)
            targets = [(4.0 * np.cos(a), 4.0 * np.sin(a)) for a in angles]
            fig, ax = plt.subplots(figsize=(6.5, 6.5), constrained_layout=True)
            for k, (step, p) in enumerate(snaps):
                policy = ppo.load_policy(p)
                for j, path_xz in enumerate(rollout_to_targets(policy, db, targets, seed=seed)):
                    ax.plot(path_xz[:, 0], path_xz[:, 1], color=f"C{k + 1}", lw=1.5,
                            label=f"{step:,} steps" if j == 0 else None)
            for tx, tz in targets:
                ax.add_patch(plt.Circle((tx, tz), 0.5, color="crimson", alpha=0.3))
                ax.plot(tx, tz, "x", color="crimson")
            ax.plot(0, 0, "ko")
            ax.set_aspect("equal")
            ax.set_xlabel("x (m)")
            ax.set_ylabel("z (m)")
            ax.grid(alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
            ax.set_title("top-down paths of checkpoints toward the same targets")
            path = out_dir / "trajectories.png"
            _save(fig, path)
            plt.close(fig)
            written.append(path)
    return written


def _save(fig, path: Path) -> None:
    """Save a figure atomically (a PNG is complete or absent)."""
    from ..io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
