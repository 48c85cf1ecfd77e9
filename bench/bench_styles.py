"""One controller for every style (issue 26, docs/styles.md): the goals, measured in one run.

    python bench/bench_styles.py --db all.npz --out runs/styles           # all shared data, tagged
    python bench/bench_styles.py --db all.npz --out runs/styles --no-specialists

``all.npz`` is ``mmrl db build ../shared/data/bandai-namco-2 -o all.npz`` (the Bandai-Namco clips
are tagged style, content and gait automatically). The bench:

1. trains one policy ``mmrl train plane --db all.npz --tags style --seconds S`` (reused if
   OUT/multi exists);
2. evaluates it per request, ``style=S`` and ``style=S & gait=walk`` for each of the seven styles,
   on the same episodes (``--episodes``, evaluation seed ``--eval-seed``): success, time to
   target, mean speed, foot sliding IK off and on, transitions/s, pose-jump p99 and the share of
   shown frames from the requested clips (fidelity);
3. runs each style's joystick line (five speeds over that style's own walk-to-run range, under the
   same request, same episodes) and reads it at the policy's time to target;
4. trains a specialist per style, on that style's clips alone, with the multi-style policy's own
   number of steps and recipe (what a conditioned run adds, ``target_kl``, and ``--set``), and
   evaluates it on the same episodes (``--no-specialists`` skips it);
5. switches the request of one continuous character every ``--switch-seconds`` through the styles
   (``--switch-rounds`` times, 105 switches by default)
   and measures the frames until the played clip carries the new request, and the pose-jump p99
   over the decisions after a switch, against the joystick's pose-jump p99;
6. measures the size and load time of the database file and the runtime file with tags, next to
   the same without them;
7. draws the seven styles walking to the same target from the same start (docs/styles.png).

Prints markdown tables and writes OUT/styles.json.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

KEYS = ("success_rate", "mean_time_to_target_s", "mean_speed_m_per_s", "foot_sliding_ik_off_cm_per_s",
        "foot_sliding_cm_per_s", "transitions_per_s", "pose_jump_p99_cm", "request_fidelity")


def train(cli, db_path: Path, out: Path, extra, seed: int) -> None:
    if (out / "latest.pt").exists():
        return
    code = cli(["train", "plane", "--db", str(db_path), "--seed", str(seed), "--out", str(out), "--no-progress",
                *extra])
    if code != 0:
        raise SystemExit(f"training {out} failed ({code})")


def styles_of(db) -> list:
    return [t.partition("=")[2] for t in db.tag_names if t.startswith("style=")]


def switch_run(task, db, policy, config, styles, seconds_each: float, seed: int, rounds: int = 3) -> dict:
    """One continuous character switching style every ``seconds_each`` s: frames from a switch
    until the shown frame's clip carries the new request, and the pose jumps over the two
    decisions after each switch (the decision that switches, and the blend after it)."""
    from mmrl import _core, metrics
    from mmrl.rollout import FullPath, policy_actions

    run = FullPath(task, db, config=config, seed=seed, record=True, continuous=True, request=f"style={styles[0]}")
    F = int(config.frames_per_step)
    steps_each = max(3, int(round(seconds_each * db.fps / F)))
    delays, starts = [], []
    rng = np.random.default_rng(seed)
    shown_total = 0
    for k in range(len(styles) * rounds):
        request = f"style={styles[(k + 1) % len(styles)]}"
        run.set_request(request)
        clips = np.asarray(_core.select_request(db._db, request)[1], bool)
        starts.append(shown_total)
        delay = None
        for s in range(steps_each):
            if s % 10 == 0:
                x, z, _ = run.character.root
                run.set_target(x + rng.uniform(-4, 4), z + rng.uniform(-4, 4))
            out = run.step(policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1))
            frames = out["res"].frames
            if delay is None:
                inside = np.flatnonzero(clips[db.frame_clip[frames]])
                if inside.size:
                    delay = shown_total + int(inside[0]) + 1 - starts[-1]
            shown_total += frames.size
            if out["done"]:
                run.continue_from_character()
        delays.append(delay)
    rec = run.recording()
    jumps = metrics.pose_jumps(rec["positions"], rec["roots"], rec["frames"], db)
    near = np.zeros(len(jumps), bool)
    for s0 in starts:
        near[s0:s0 + 2 * F + 1] = True
    return {"switches": len(starts), "frames_to_inside": delays,
            "max_frames_to_inside": None if any(d is None for d in delays) else int(max(delays)),
            "pose_jump_p99_after_switches_cm": float(np.percentile(jumps[near[:len(jumps)]], 99)),
            "pose_jump_p99_cm": float(np.percentile(jumps, 99))}


def sizes(db, config, run_dir: Path, tmp: Path) -> dict:
    """The database file with and without its tags (size, load time), and the runtime file of the
    multi-style run (size, load time, memory) with the bytes its tag sections take."""
    import mmrl
    from mmrl import _core
    from mmrl.cli import main as cli

    out = {}
    state = {k: v for k, v in db._state().items() if k not in ("tag_names", "clip_tags")}
    for name, d in (("with tags", db), ("without tags", mmrl.Database(_core.Database.from_state(state)))):
        npz = tmp / f"db-{name.replace(' ', '-')}.npz"
        d.save(npz)
        t0 = time.perf_counter()
        mmrl.Database.load(npz)
        out[name] = {"db_file_mb": npz.stat().st_size / 1e6, "db_load_s": time.perf_counter() - t0}
    ctl = tmp / "multi.mmrl"
    if cli(["export", str(run_dir), "-o", str(ctl)]) != 0:
        raise SystemExit("export failed")
    t0 = time.perf_counter()
    c = _core.RuntimeController.load(str(ctl))
    out["runtime"] = {"file_mb": ctl.stat().st_size / 1e6, "load_s": time.perf_counter() - t0,
                      "memory_mb": c.memory_bytes / 1e6,
                      "tag_bytes": int(db.clip_tags.size + sum(len(t) + 1 for t in db.tag_names))}
    return out


def figure(task, db, policy, config, styles, path: Path, target=(4.0, 3.0), seed: int = 0) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mmrl.io import atomic_path
    from mmrl.rollout import FullPath, policy_actions

    times = {}
    fig, ax = plt.subplots(figsize=(6, 5), constrained_layout=True)
    for k, style in enumerate(styles):
        run = FullPath(task, db, config=config, seed=seed, record=True, continuous=True, request=f"style={style}")
        # The same start for every style: each request's first valid frame, at the origin facing +Z.
        start = int(np.flatnonzero(np.asarray(run.request_clips)[db.frame_clip] & db.valid_mask)[0])
        run.env.set_state(0, start, 0.0, 0.0, 0.0)
        run.character.reset(start, (0.0, 0.0), 0.0)
        run.set_target(*target)
        for _ in range(100):
            out = run.step(policy_actions(policy, run.obs[None], layout=run.env.observation_layout).reshape(-1))
            if out["done"]:
                break
        roots = run.recording()["roots"]
        t = len(roots) / db.fps if out.get("success") or out["terminated"] else None
        times[style] = t
        ax.plot(roots[:, 0], roots[:, 1], color=f"C{k}", label=f"{style} ({t:.2f} s)" if t else f"{style} (missed)")
    ax.plot([0], [0], "ko")
    ax.add_patch(plt.Circle(target, float(config.success_radius), color="k", fill=False))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title("one policy, seven styles, the same target")
    ax.legend(fontsize=7)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return times


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", required=True, help="all shared data, built by 'mmrl db build' (tagged)")
    p.add_argument("--out", default="runs/styles")
    p.add_argument("--seconds", type=float, default=180.0, help="the multi-style policy's training budget")
    p.add_argument("--tags", default="style", help="the groups the policy is conditioned on")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--eval-seed", type=int, default=1)
    p.add_argument("--no-specialists", action="store_true")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a training setting for the multi-style policy and the specialists alike (mmrl train --set)")
    p.add_argument("--data", default=None, help="the shared data folder (DATA/<style>/*.bvh), when the database's "
                   "clip paths do not resolve from here")
    p.add_argument("--switch-seconds", type=float, default=2.0)
    p.add_argument("--switch-rounds", type=int, default=15,
                   help="rounds through the styles in each switch run (15 = 105 switches: a p99 over 21 "
                        "switches moved 0.5-1.7x between evaluation seeds)")
    p.add_argument("--figure", default="docs/styles.png")
    p.add_argument("--switches-of", default=None, metavar="RUN",
                   help="only the switch run: RUN's policy and the walking joystick through the same switches")
    args = p.parse_args()

    import mmrl
    from mmrl.cli import main as cli
    from mmrl.io import atomic_write_text
    from mmrl.rl.policies import JoystickPolicy
    from mmrl.eval.reference import against_line, joystick_line, joystick_speeds
    from mmrl.rollout import evaluate_full_path
    from mmrl.runs import RunDir

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    db_path = Path(args.db)
    db = mmrl.Database.load(db_path)
    styles = styles_of(db)
    if not styles:
        raise SystemExit(f"{db_path}: no style tags (build it with 'mmrl db build ../shared/data/bandai-namco-2')")
    task = mmrl.get_task("plane")
    if args.switches_of:
        rd = RunDir(args.switches_of)
        cfg = rd.task_config(task)
        res = {"policy": switch_run(task, db, rd.policy(), cfg, styles, args.switch_seconds, args.eval_seed,
                                    args.switch_rounds),
               "joystick": switch_run(task, db, JoystickPolicy.preset(db, "joystick"), cfg, styles,
                                      args.switch_seconds, args.eval_seed, args.switch_rounds)}
        res["ratio_after_switches"] = (res["policy"]["pose_jump_p99_after_switches_cm"] /
                                       res["joystick"]["pose_jump_p99_after_switches_cm"])
        print(json.dumps(res, indent=1))
        return
    multi = out / "multi"
    t0 = time.perf_counter()
    sets = [a for kv in args.set for a in ("--set", kv)]
    train(cli, db_path, multi, ["--request-groups", args.tags, "--seconds", str(args.seconds), *sets], args.seed)
    rd = RunDir(multi)
    policy, config = rd.policy(), rd.task_config(task)
    import csv

    with open(multi / "metrics.csv") as fh:
        steps = int(list(csv.DictReader(fh))[-1]["step"])
    # The specialists train with the multi-style policy's recipe: what a conditioned run adds by
    # default (the task's request_ppo_defaults, e.g. target_kl) is passed to them as well.
    recipe = []
    for k in task.request_ppo_defaults:
        v = rd.config["ppo"][k]
        recipe += ["--set", f"{k}={'none' if v is None else v}"]
    result = {"db": str(db_path), "styles": styles, "tags": args.tags, "train_seconds": args.seconds, "set": args.set,
              "train_steps": steps, "per_request": {}, "specialists": {}, "lines": {}}

    def ev(pol, d, request, cfg):
        r = evaluate_full_path(task, d, pol, episodes=args.episodes, seed=args.eval_seed, config=cfg, request=request)
        return {k: r.get(k) for k in KEYS}

    for style in styles:
        for req in (f"style={style}", f"style={style} & gait=walk"):
            row = ev(policy, db, req, config)
            line = joystick_line(task, db, speeds=joystick_speeds(db, 5, request=req), episodes=args.episodes,
                                 seed=args.eval_seed, config=config, request=req)
            row.update({k: v for k, v in against_line(row, line).items() if k != "joystick_line"})
            result["per_request"][req] = row
            result["lines"][req] = line
            print(f"{req}: {json.dumps(row)}", flush=True)
    if not args.no_specialists:
        for style in styles:
            clips = [n for n, on in zip(db.clip_names, db.clip_tags[:, db.tag_names.index(f"style={style}")]) if on]
            sdb_path = out / f"only-{style}.npz"
            if not sdb_path.exists():
                if args.data:  # the clips again from where they are now (a database keeps the paths it was built from)
                    clips = [str(Path(args.data) / style / Path(c).name) for c in clips]
                sdb = mmrl.Database.from_bvh(clips)
                sdb.save(sdb_path)
            sdb = mmrl.Database.load(sdb_path)
            run = out / f"only-{style}"
            train(cli, sdb_path, run, ["--steps", str(steps), *recipe, *sets], args.seed)
            row = ev(RunDir(run).policy(), sdb, "", RunDir(run).task_config(task))
            result["specialists"][style] = row
            multi_t = result["per_request"][f"style={style}"]["mean_time_to_target_s"]
            print(f"specialist {style}: {json.dumps(row)}; multi-style time {multi_t}", flush=True)
    result["switch"] = switch_run(task, db, policy, config, styles, args.switch_seconds, args.eval_seed,
                                  args.switch_rounds)
    joy = evaluate_full_path(task, db, JoystickPolicy.preset(db, "joystick"), episodes=args.episodes,
                             seed=args.eval_seed, config=config.replace(request_groups=""))
    result["switch"]["joystick_pose_jump_p99_cm"] = joy.get("pose_jump_p99_cm")
    # The peer through the same switches: the walking joystick under the same requests and targets.
    result["switch"]["joystick_switch"] = switch_run(task, db, JoystickPolicy.preset(db, "joystick"), config, styles,
                                                     args.switch_seconds, args.eval_seed, args.switch_rounds)
    result["sizes"] = sizes(db, config, multi, out)
    result["figure_times"] = figure(task, db, policy, config, styles, Path(args.figure))
    result["bench_seconds"] = time.perf_counter() - t0
    atomic_write_text(out / "styles.json", json.dumps(result, indent=1))

    f = lambda v, p=2: "n/a" if v is None else f"{v:.{p}f}"  # noqa: E731
    print(f"\none policy, --tags {args.tags}, {steps:,} steps in {args.seconds:g} s; {args.episodes} episodes per "
          "request\n")
    print("| request | success | time to target | speed m/s | IK off | line there | IK off / line | IK on | "
          "transitions/s | pose jump p99 | inside | specialist's time | multi / specialist |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for req, r in result["per_request"].items():
        style = req.split("&")[0].strip().partition("=")[2]
        spec = result["specialists"].get(style) if "&" not in req else None
        st = spec.get("mean_time_to_target_s") if spec else None
        ratio = (r["mean_time_to_target_s"] / st) if st and r["mean_time_to_target_s"] else None
        print(f"| {req} | {100 * r['success_rate']:.0f}% | {f(r['mean_time_to_target_s'])} | "
              f"{f(r['mean_speed_m_per_s'])} | {f(r['foot_sliding_ik_off_cm_per_s'], 1)} | "
              f"{f(r['joystick_line_sliding_ik_off_cm_per_s'], 1)} | {f(r['sliding_ik_off_vs_joystick_line'])} | "
              f"{f(r['foot_sliding_cm_per_s'], 2)} | {f(r['transitions_per_s'])} | {f(r['pose_jump_p99_cm'], 1)} | "
              f"{f(100 * r['request_fidelity'], 2) if r['request_fidelity'] is not None else 'n/a'}% | {f(st)} | "
              f"{f(ratio, 3)} |")
    sw = result["switch"]
    print(f"\nswitches: {sw['switches']}, frames until the new style plays: max {sw['max_frames_to_inside']} "
          f"(one decision = {config.frames_per_step}); pose-jump p99 over the two decisions after each switch "
          f"{f(sw['pose_jump_p99_after_switches_cm'], 1)} cm, over the whole run {f(sw['pose_jump_p99_cm'], 1)} cm, "
          f"the joystick's {f(sw['joystick_pose_jump_p99_cm'], 1)} cm")
    sz = result["sizes"]
    for name in ("with tags", "without tags"):
        print(f"database file {name}: {sz[name]['db_file_mb']:.2f} MB, loads in {sz[name]['db_load_s']:.2f} s")
    rt = sz["runtime"]
    print(f"runtime file: {rt['file_mb']:.1f} MB, loads in {rt['load_s']:.2f} s, {rt['memory_mb']:.1f} MB loaded; "
          f"its tags take {rt['tag_bytes']:,} bytes")
    print(f"wrote {out / 'styles.json'} and {args.figure} ({result['bench_seconds']:.0f} s)")


if __name__ == "__main__":
    main()
