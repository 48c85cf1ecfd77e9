"""Soak runs (issue 18, item 3): long runs with the resident memory (RSS) sampled to CSV and a
verdict on whether it stays flat.

    python bench/soak.py env    # 10M batched env steps of each task (steps/s)
    python bench/soak.py train  # a 30-minute `mmrl train plane` (RSS of the training process)
    python bench/soak.py play   # a 30-minute `mmrl play` session driven by scripted clicks
    python bench/soak.py all    # the three, one after the other

``--scale S`` multiplies every length (steps, minutes): tests/test_soak.py runs all three at a
tiny scale to prove the script works. RSS (VmRSS of /proc/PID/status, MB) is sampled every
``--interval`` seconds into ``OUT/soak_<part>.csv`` (t_s, rss_mb, progress). The verdict line
fits a least-squares line to the last two thirds of the samples (the first third holds the
warm-up: allocator pools, caches, the first checkpoint) and calls the run FLAT when its slope
is under ``--threshold`` MB/hour. Run one part at a time on a shared machine, under nice.

The play session is ``mmrl play``'s own loop (``PlayApp`` on a viser ``Scene``: the live
session, the scene updates and the quality panel at 30 fps) with no browser attached; the
script clicks the ground every 2 s, toggles IK and inertialization every 20 s and switches
between the trained and the joystick policy every 60 s (on obstacles: drags an obstacle and
pauses them too). Without ``--run`` it plays a small plane policy trained first (20k steps).
"""
from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ENV_STEPS = 10_000_000
TRAIN_MINUTES = PLAY_MINUTES = 30.0


class RssSampler:
    """Samples the RSS of ``pid`` every ``interval`` seconds (in a thread) into ``csv_path``;
    ``progress()`` gives the third column (env steps, frames...)."""

    def __init__(self, pid: int, csv_path: Path, interval: float, progress=lambda: 0):
        self.pid, self.path, self.interval, self.progress = pid, Path(csv_path), interval, progress
        self.samples: list = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def rss_mb(self) -> float:
        with open(f"/proc/{self.pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
        return float("nan")

    def _loop(self) -> None:
        start = time.monotonic()
        with open(self.path, "w", newline="") as file:
            out = csv.writer(file)
            out.writerow(["t_s", "rss_mb", "progress"])
            while True:
                try:
                    row = (time.monotonic() - start, self.rss_mb(), self.progress())
                except (FileNotFoundError, ProcessLookupError):
                    return  # the process ended
                if not row[1] == row[1]:
                    return  # a zombie: its status has no VmRSS any more
                self.samples.append(row)
                out.writerow([f"{row[0]:.2f}", f"{row[1]:.2f}", row[2]])
                file.flush()
                if self._stop.wait(self.interval):
                    return

    def __enter__(self) -> "RssSampler":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def verdict(name: str, samples: list, threshold_mb_per_h: float) -> str:
    """One line: RSS at the start and end and the slope (MB/hour) over the last two thirds."""
    if len(samples) < 3:
        return f"soak {name}: {len(samples)} RSS samples, too few for a slope (run longer or sample more often)"
    t = np.array([s[0] for s in samples])
    rss = np.array([s[1] for s in samples])
    tail = slice(len(samples) // 3, None)
    slope = float(np.polyfit(t[tail] / 3600.0, rss[tail], 1)[0]) if np.ptp(t[tail]) > 0 else 0.0
    flat = "FLAT" if abs(slope) < threshold_mb_per_h else "GROWING" if slope > 0 else "SHRINKING"
    return (f"soak {name}: RSS {rss[0]:.1f} -> {rss[-1]:.1f} MB (max {rss.max():.1f}) over {t[-1]:.0f} s; "
            f"slope of the last 2/3: {slope:+.1f} MB/h (threshold {threshold_mb_per_h:g}): {flat}")


# ----------------------------------------------------------------------------- the parts

def soak_env(args, out: Path) -> list:
    import mmrl

    db = mmrl.Database.load(args.db) if args.db else mmrl.default_database()
    lines = []
    for name in args.env_tasks:
        env = mmrl.get_task(name).make_vector_env(args.envs, db=db)
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        low, high = env.single_action_space.low, env.single_action_space.high
        total = max(args.envs, int(ENV_STEPS * args.scale))
        done = [0]
        with RssSampler(os.getpid(), out / f"soak_env_{name}.csv", args.interval, lambda: done[0]) as sampler:
            start = time.perf_counter()
            while done[0] < total:
                actions = rng.uniform(low, high, (args.envs, low.size)).astype(np.float32)
                env.step(actions)
                done[0] += args.envs
            seconds = time.perf_counter() - start
        env.close()
        lines.append(f"soak env {name}: {done[0]:,} steps ({args.envs} envs) in {seconds:.1f} s = "
                     f"{done[0] / seconds:,.0f} steps/s")
        lines.append(verdict(f"env {name}", sampler.samples, args.threshold))
        print(lines[-2], "\n" + lines[-1], flush=True)
    return lines


def soak_train(args, out: Path) -> list:
    seconds = max(1.0, TRAIN_MINUTES * 60.0 * args.scale)
    run = out / "soak_train_run"
    cmd = [sys.executable, "-m", "mmrl", "train", args.task, "--seconds", f"{seconds:g}", "--out", str(run),
           "--no-progress", "--set", "checkpoint_interval_steps=50000"]
    if (run / "latest.pt").exists():
        cmd = [sys.executable, "-m", "mmrl", "train", args.task, "--resume", str(run), "--seconds", f"{seconds:g}",
               "--no-progress"]
    if args.db and not (run / "latest.pt").exists():
        cmd += ["--db", args.db]
    log = open(out / "soak_train.log", "w")
    child = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
    with RssSampler(child.pid, out / "soak_train.csv", args.interval) as sampler:
        code = child.wait()
    log.close()
    if code != 0:
        raise SystemExit(f"soak train: mmrl train exited with {code}; see {out / 'soak_train.log'}")
    steps = _last_step(run / "metrics.csv")
    lines = [f"soak train {args.task}: {steps:,} steps in {seconds:.0f} s of training (mmrl train exit 0)",
             verdict(f"train {args.task}", sampler.samples, args.threshold)]
    print("\n".join(lines), flush=True)
    return lines


def _last_step(metrics: Path) -> int:
    rows = list(csv.DictReader(metrics.read_text().splitlines())) if metrics.exists() else []
    return int(rows[-1]["step"]) if rows else 0


def _play_session(args, out: Path):
    """(task, db, policy, config): the run of --run, or a small plane policy trained now."""
    from mmrl.cli import main
    from mmrl.runs import RunDir

    run_dir = Path(args.run) if args.run else out / "soak_play_policy"
    if not args.run and not (run_dir / "latest.pt").exists():
        steps = str(max(2048, int(20_000 * min(1.0, args.scale * 100))))
        if main(["train", "plane", "--steps", steps, "--out", str(run_dir), "--no-progress"]) != 0:
            raise SystemExit("soak play: could not train the policy to play")
    run = RunDir(run_dir)
    return run.task, run.database(), run.policy(), run.task_config(run.task)


def soak_play(args, out: Path) -> list:
    import torch

    from mmrl.viewer.live import LiveSession
    from mmrl.viewer.play_app import PlayApp
    from mmrl.viewer.scene import Scene

    torch.set_num_threads(1)  # as mmrl play
    task, db, policy, config = _play_session(args, out)
    session = LiveSession(task, db, policy, config=config, seed=0)
    app = PlayApp(Scene("127.0.0.1", args.port, title="mmrl soak"), session)
    seconds = max(1.0, PLAY_MINUTES * 60.0 * args.scale)
    stop = threading.Event()
    player = threading.Thread(target=app.run, args=(stop,), daemon=True)
    rng = np.random.default_rng(0)
    clicks = 0
    with RssSampler(os.getpid(), out / "soak_play.csv", args.interval, lambda: app.frames) as sampler:
        player.start()
        start = time.monotonic()
        while (elapsed := time.monotonic() - start) < seconds:
            _scripted_input(app, session, rng, clicks)
            clicks += 1
            stop.wait(min(2.0, max(0.0, seconds - elapsed)))
        stop.set()
        player.join()
    session.close()
    lines = [f"soak play {task.name}: {app.frames:,} frames in {seconds:.0f} s, {clicks} scripted inputs; "
             + app.timing_report().splitlines()[0], verdict(f"play {task.name}", sampler.samples, args.threshold)]
    print("\n".join(lines), flush=True)
    return lines


def _scripted_input(app, session, rng, k: int) -> None:
    """Input number k (one every 2 s): a ground click, plus every 10th a toggle of IK and
    inertialization, every 30th a policy switch; on obstacles a drag and a pause."""
    x, z, _ = session.root
    app.click(float(x + rng.uniform(-6, 6)), float(z + rng.uniform(-6, 6)))
    if k % 10 == 9:
        session.set_options(ik=bool(k % 20 == 9), inertialization=bool(k % 40 < 20))
    if k % 30 == 29:
        session.set_policy("joystick" if session.policy_name == "trained" else "trained")
    if session.has_obstacles and k % 5 == 4:
        app.pick_obstacle(float(x + 2.0), float(z))
        if app.picked is not None:
            session.move_obstacle(app.picked, float(x + rng.uniform(-4, 4)), float(z + rng.uniform(-4, 4)))
        session.pause_obstacles(bool(k % 10 == 4))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("part", choices=("env", "train", "play", "all"))
    p.add_argument("--scale", type=float, default=1.0, help="multiplies every length (default 1: 10M steps, 30 min)")
    p.add_argument("--interval", type=float, default=5.0, help="seconds between RSS samples (default 5)")
    p.add_argument("--threshold", type=float, default=20.0, help="MB/hour below which RSS counts as flat")
    p.add_argument("--out", default=None, help="directory for the CSVs and logs (default: a new temp dir)")
    p.add_argument("--envs", type=int, default=256, help="batched envs of the env part (default 256)")
    p.add_argument("--task", default="plane", help="task of the train part (default plane)")
    p.add_argument("--env-tasks", nargs="+", default=["plane", "obstacles"], help="tasks of the env part (default both)")
    p.add_argument("--db", default=None, help="a database .npz (default: the synthetic data)")
    p.add_argument("--run", default=None, help="the run the play part plays (default: a small plane run)")
    p.add_argument("--port", type=int, default=8091, help="the play part's viser port (default 8091)")
    args = p.parse_args(argv)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="mmrl-soak-"))
    out.mkdir(parents=True, exist_ok=True)
    parts = ("env", "train", "play") if args.part == "all" else (args.part,)
    lines = []
    for part in parts:
        lines += {"env": soak_env, "train": soak_train, "play": soak_play}[part](args, out)
    (out / "soak_summary.txt").write_text("\n".join(lines) + "\n")
    print(f"CSVs and summary in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
