"""Fork server for tests/test_kill_resume.py: runs the ``mmrl`` command line
(``mmrl.cli.main(argv)``) in forked children with phase markers, so that the parent can SIGKILL
a child inside a chosen phase. Test-only instrumentation: the code under test is unchanged; the
wrappers below only report and slow down, then call the real functions.

Why a fork server: a fresh ``mmrl train`` process spends ~5 s importing torch (and
torch._dynamo, which the Adam optimizer imports) before its first step; this process imports
everything once and forks a child per run (~0.1 s), so the test can afford dozens of kills.
Each child is a new process: it reads everything it resumes from disk, as ``mmrl`` would.

Protocol: one JSON request per line on stdin, ``{"argv": [...], "cwd": DIR, "log": FILE,
"slow_write_s": S, "slow_step_s": S, "easy_curriculum": BOOL}``. On stdout, per request: ``pid <PID>``, the
child's markers, then ``exit <STATUS>`` (``os.waitpid`` status: killed children report
``-<signal>``). The child's own stdout and stderr go to ``log``.

Markers: one line ``<phase> enter|exit <monotonic seconds>`` per event, written with a single
``os.write`` (a kill never splits a line). Phases:

- ``startup``: from ``main`` being called to the first rollout, npz save or download (data,
  envs, config.json, checkpoint load, metrics.csv trim; the BVH import of ``db build``);
- ``rollout``: ``mmrl.rl.ppo.collect_rollout``;
- ``update``: ``mmrl.rl.ppo._learn`` (advantages, the PPO update, counters, callbacks);
- ``log``: ``MetricsLogger.write`` (one metrics.csv row);
- ``checkpoint``: each ``save_checkpoint`` (``latest.pt``, ``snapshot_<N>.pt``);
- ``save``: ``Database.save`` (``mmrl db build``'s npz);
- ``download``: one file of ``mmrl data fetch``.

``slow_step_s``: seconds to sleep before each env step of a rollout (a rollout of 16 steps
takes ~4 ms otherwise, too short to aim at).
``slow_write_s``: seconds to sleep before each ``write`` into a file opened by
``mmrl.io.atomic_open`` (checkpoints, npz, downloads, metrics trims), so that a kill lands
inside a write and not only between writes.
``easy_curriculum``: the obstacles curriculum advances once any episode of the last 4 finished
at the current stage succeeded (by default 40% of 200, which takes ~300k steps), so that a
short run crosses several stages.
"""
import contextlib
import os
import sys
import time

FD = 1  # the child's markers; its sys.stdout goes to the request's log
SLOW = 0.0
SLOW_STEP = 0.0


def mark(phase: str, event: str) -> None:
    os.write(FD, f"{phase} {event} {time.monotonic():.6f}\n".encode())


def phased(phase, function):
    def wrapper(*args, **kwargs):
        mark(phase, "enter")
        result = function(*args, **kwargs)
        mark(phase, "exit")
        return result

    wrapper.__wrapped__ = function
    return wrapper


class SlowFile:
    """The real file object; each write sleeps SLOW seconds first."""

    def __init__(self, file):
        self._file = file

    def write(self, data):
        time.sleep(SLOW)
        return self._file.write(data)

    def __getattr__(self, name):
        return getattr(self._file, name)


def instrument() -> None:
    import mmrl.rl.checkpoints
    import mmrl.motion.data
    import mmrl.motion.database
    import mmrl.io
    import mmrl.logs
    import mmrl.rl.ppo

    started = []

    def first_work(function):  # the first rollout, npz save or download ends the startup
        def wrapper(*args, **kwargs):
            if not started:
                started.append(1)
                mark("startup", "exit")
            return function(*args, **kwargs)

        return wrapper

    def slow_steps(function):  # each env step of a rollout sleeps SLOW_STEP seconds first
        def wrapper(envs, *args, **kwargs):
            if SLOW_STEP > 0 and "step" not in vars(envs):
                real_step = envs.step

                def step(actions):
                    time.sleep(SLOW_STEP)
                    return real_step(actions)

                envs.step = step
            return function(envs, *args, **kwargs)

        return wrapper

    mmrl.rl.ppo.collect_rollout = first_work(phased("rollout", slow_steps(mmrl.rl.ppo.collect_rollout)))
    mmrl.rl.ppo._learn = phased("update", mmrl.rl.ppo._learn)
    mmrl.logs.MetricsLogger.write = phased("log", mmrl.logs.MetricsLogger.write)
    save = phased("checkpoint", mmrl.rl.checkpoints.save_checkpoint)
    mmrl.rl.checkpoints.save_checkpoint = mmrl.rl.ppo.save_checkpoint = save
    mmrl.motion.database.Database.save = first_work(phased("save", mmrl.motion.database.Database.save))
    mmrl.motion.data._download = first_work(phased("download", mmrl.motion.data._download))
    real_open = mmrl.io.atomic_open

    @contextlib.contextmanager
    def slow_atomic_open(*args, **kwargs):
        with real_open(*args, **kwargs) as file:
            yield SlowFile(file) if SLOW > 0 else file

    for module in (mmrl.io, mmrl.rl.checkpoints, mmrl.motion.data, mmrl.logs):
        module.atomic_open = slow_atomic_open


def easy_curriculum() -> None:
    import mmrl.tasks.curriculum as curriculum

    real_init = curriculum.Curriculum.__init__

    def easy_init(self, *args, **kwargs):
        kwargs.update(threshold=0.0, window=4)
        real_init(self, *args, **kwargs)

    curriculum.Curriculum.__init__ = easy_init


def child(request: dict) -> int:
    global FD, SLOW, SLOW_STEP
    FD = os.dup(1)
    log = os.open(request["log"], os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.chdir(request["cwd"])
    SLOW = float(request.get("slow_write_s", 0.0))
    SLOW_STEP = float(request.get("slow_step_s", 0.0))
    if request.get("easy_curriculum"):
        easy_curriculum()
    from mmrl.cli import main as cli_main

    mark("startup", "enter")
    code = cli_main(request["argv"])
    mark("done", "exit")
    return code


def serve() -> None:
    import json

    # Import what a run imports, once: torch, torch._dynamo (Adam imports it), TensorBoard.
    import torch._dynamo  # noqa: F401
    import mmrl.cli  # noqa: F401
    import mmrl.commands.train  # noqa: F401
    try:
        import torch.utils.tensorboard  # noqa: F401
    except ImportError:
        pass
    instrument()
    for line in sys.stdin:
        request = json.loads(line)
        sys.stdout.flush()
        pid = os.fork()
        if pid == 0:
            code = 70
            try:
                code = child(request)
            except BaseException:  # the parent reads the traceback in the log
                import traceback

                traceback.print_exc()
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
        os.write(1, f"pid {pid}\n".encode())
        _, status = os.waitpid(pid, 0)
        code = -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)
        os.write(1, f"exit {code}\n".encode())


if __name__ == "__main__":
    serve()
