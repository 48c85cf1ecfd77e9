"""Helpers of tests/test_kill_resume.py (and bench/kill_resume.py): a fork server that runs
``mmrl`` commands and SIGKILLs them inside a chosen phase (tests/_kill_child.py), and the
checks of a training run directory after each kill."""
from __future__ import annotations

import csv
import json
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

CHILD = Path(__file__).resolve().parent / "_kill_child.py"


@dataclass
class Outcome:
    """One child run: its exit code (-9 when killed), the phases open when it died, and the
    phase it was meant to die in."""

    code: int
    killed_in: tuple = ()
    target: Optional[str] = None
    markers: list = field(default_factory=list)

    @property
    def killed(self) -> bool:
        return self.code == -signal.SIGKILL


class ForkServer:
    """``run(argv, kill_at=(phase, occurrence, delay_s))`` runs ``mmrl argv`` in a forked child
    and kills it ``delay_s`` after the ``occurrence``-th time it enters ``phase``."""

    def __init__(self, workdir: Path, timeout: float = 180.0):
        self.workdir = Path(workdir)
        self.timeout = timeout
        self.proc = subprocess.Popen([sys.executable, str(CHILD)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     cwd=self.workdir)
        self.buffer = b""
        self.count = 0

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=30)
        self.proc.stdout.close()

    def _line(self, deadline: float) -> str:
        fd = self.proc.stdout.fileno()
        while b"\n" not in self.buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                raise TimeoutError(f"no progress from the fork server within {self.timeout} s (a hang?)")
            chunk = os.read(fd, 65536)
            if not chunk:
                raise RuntimeError(f"the fork server died (exit {self.proc.poll()})")
            self.buffer += chunk
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line.decode()

    def run(self, argv, *, kill_at=None, slow_write_s: float = 0.0, slow_step_s: float = 0.0,
            easy_curriculum: bool = False) -> Outcome:
        self.count += 1
        log = self.workdir / f"child{self.count:03d}.log"
        request = {"argv": [str(a) for a in argv], "cwd": str(self.workdir), "log": str(log),
                   "slow_write_s": slow_write_s, "slow_step_s": slow_step_s, "easy_curriculum": easy_curriculum}
        self.proc.stdin.write((json.dumps(request) + "\n").encode())
        self.proc.stdin.flush()
        deadline = time.monotonic() + self.timeout
        pid, seen, kill_due, markers, open_phases = None, 0, None, [], []
        while True:
            line = self._line(deadline)
            word = line.split()
            if word[0] == "pid":
                pid = int(word[1])
            elif word[0] == "exit":
                code = int(word[1])
                break
            else:
                phase, event = word[0], word[1]
                markers.append((phase, event))
                if event == "enter":
                    open_phases.append(phase)
                    if kill_at is not None and phase == kill_at[0]:
                        seen += 1
                        if seen == kill_at[1]:
                            kill_due = time.monotonic() + kill_at[2]
                elif phase in open_phases:
                    open_phases.remove(phase)
            if kill_due is not None and pid is not None:
                time.sleep(max(0.0, kill_due - time.monotonic()))
                os.kill(pid, signal.SIGKILL)
                kill_due = None
        if code not in (0, -signal.SIGKILL):
            raise AssertionError(f"mmrl {' '.join(request['argv'])} exited with {code}:\n{log.read_text()[-3000:]}")
        return Outcome(code, tuple(open_phases) if code == -signal.SIGKILL else (),
                       kill_at[0] if kill_at else None, markers)


# ----------------------------------------------------------------------------- run directory checks

@dataclass
class Saved:
    """What latest.pt held when a child died."""

    step: int
    iteration: int
    stage: Optional[int]


def visible(directory: Path, pattern: str):
    return sorted(p for p in Path(directory).glob(pattern) if not p.name.startswith("."))


def read_metrics(run: Path) -> list:
    path = Path(run) / "metrics.csv"
    if not path.exists():
        return []
    text = path.read_text()
    assert text.count("step,wall_s") <= 1, "metrics.csv holds two headers"
    return list(csv.DictReader(text.splitlines()))


def check_run_dir(run: Path, batch: int, previous: Saved) -> Saved:
    """After a kill: every checkpoint file loads (none torn), latest.pt never went back, every
    snapshot latest.pt lists exists, config.json parses, and metrics.csv holds exactly one row per
    iteration up to the checkpoint's step (rows after it are dropped on resume)."""
    from mmrl.rl.checkpoints import load_checkpoint

    states = {p.name: load_checkpoint(p) for p in visible(run, "*.pt")}  # raises on a torn file
    if (Path(run) / "config.json").exists():
        json.loads((Path(run) / "config.json").read_text())
    latest = states.get("latest.pt")
    saved = Saved(0, 0, None)
    if latest is not None:
        stage = latest["callbacks"].get(0, {}).get("stage") if latest["callbacks"] else None
        saved = Saved(int(latest["global_step"]), int(latest["iteration"]), stage)
        assert saved.step == saved.iteration * batch
        for s in latest["snapshots"]:
            assert f"snapshot_{s}.pt" in states, f"latest.pt lists snapshot {s}, whose file is missing"
    assert saved.step >= previous.step, f"latest.pt went back from step {previous.step} to {saved.step}"
    for name, state in states.items():
        if name.startswith("snapshot_"):
            assert state["global_step"] == int(name[len("snapshot_"):-3])
    steps = [int(r["step"]) for r in read_metrics(run)]
    assert [s for s in steps if s <= saved.step] == list(range(batch, saved.step + 1, batch)), steps
    return saved


def check_finished_run(run: Path, batch: int, total: int, saves: list, snapshot_steps=()) -> list:
    """After the last (unkilled) run: one row per iteration, and for each checkpoint a child died
    with, the next row continues its step, iteration and curriculum stage. Returns the rows."""
    from mmrl.rl.checkpoints import load_checkpoint

    rows = read_metrics(run)
    assert [int(r["step"]) for r in rows] == list(range(batch, total + 1, batch))
    assert [int(r["iteration"]) for r in rows] == list(range(1, total // batch + 1))
    by_step = {int(r["step"]): r for r in rows}
    staged = "curriculum_stage" in rows[0]
    if staged:
        stages = [int(r["curriculum_stage"]) for r in rows]
        assert stages == sorted(stages), f"the curriculum stage went back: {stages}"
    for saved in saves:
        if saved.step == 0 or saved.step >= total:
            continue
        after = by_step[saved.step + batch]
        assert int(after["iteration"]) == saved.iteration + 1
        if staged:
            assert int(by_step[saved.step]["curriculum_stage"]) == saved.stage
            assert int(after["curriculum_stage"]) in (saved.stage, saved.stage + 1)
    latest = load_checkpoint(Path(run) / "latest.pt")
    assert latest["global_step"] == total
    for s in snapshot_steps:
        assert load_checkpoint(Path(run) / f"snapshot_{s}.pt")["global_step"] == s
    return rows
