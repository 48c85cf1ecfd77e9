"""``mmrl eval``, ``mmrl render`` and ``mmrl export-bvh``: run a policy on the full-path character.

They share their options: an optional training run directory (its policy, task, options and
database, read by :class:`mmrl.runs.RunDir`), ``--data``/``--db``, ``--task`` (any registered
task), ``--policy``, ``--seed``, ``--episodes`` (eval) or ``--length`` (render, export-bvh), ``--stage`` (tasks with a
curriculum), ``--no-ik`` and ``--no-inertialization``. The episodes run in
:mod:`mmrl.rollout`'s full-path loop, the same for every task.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import InputError
from ..tasks import get_task, task_names
from .db import fps_text
from .common import (add_data_options, add_deploy_set, deploy_config, bounded_int, count, database_from_args, deprecated_alias, nonnegative_float,
                     output_path, positive_float, seed)

#: Episodes of the joystick that ``mmrl eval`` runs at the policy's speed by default (the first
#: ones of the same seed): enough for its sliding, a fifth of a 100-episode evaluation.
PEER_EPISODES = 20
STANDING_EPISODES = 50  # mmrl eval --standing: episodes of the standing report (its own, the same for the joystick)

POLICIES = ("trained", "joystick", "joystick-run")


def add_shared_options(p: argparse.ArgumentParser, motion: bool) -> None:
    """The options of eval (``motion`` False: ``--episodes``) and of render and export-bvh
    (``motion`` True: ``--length``)."""
    p.add_argument("run", nargs="?", metavar="RUN",
                   help="a training run directory (its latest.pt, task, options and database)")
    add_data_options(p)
    p.add_argument("--task", choices=task_names(), default=None,
                   help="the task (default: RUN's task if RUN is given, else plane)")
    deprecated_alias(p, "--env", "--task", "task")
    staged = [n for n in task_names() if get_task(n).stages]
    p.add_argument("--stage", type=int, default=None, metavar="K",
                   help=f"curriculum stage ({', '.join(staged)}; default: the last, the hardest)")
    p.add_argument("--policy", choices=POLICIES, default=None,
                   help="trained: RUN's policy; joystick / joystick-run: a scripted stick held toward the target at "
                        "the data's walking / running speed (default: trained with RUN, else joystick)")
    p.add_argument("--seed", type=seed, default=0, help="random seed of the episodes (default: 0)")
    if motion:
        p.add_argument("--length", type=lambda t: positive_float(t, 3600), default=10.0, metavar="SECONDS",
                       help="seconds of motion to write, at most 3600, in whole decisions of 0.2 s (default: 10)")
        deprecated_alias(p, "--seconds", "--length (--seconds is a training budget)", "length", type=positive_float)
        deprecated_alias(p, "--episodes", lambda v: "it never did anything here; drop it", "ignored_episodes")
    else:
        p.add_argument("--episodes", type=bounded_int(100_000), default=20, help="evaluation episodes (default: 20)")
        deprecated_alias(p, "--seconds", lambda v: "it never did anything in eval; use --episodes", "ignored_seconds")
    p.add_argument("--no-ik", action="store_true", help="switch off foot locking and leg IK")
    p.add_argument("--no-inertialization", action="store_true", help="hard switches at transitions")
    p.add_argument("--request", default="", metavar="TAGS",
                   help="keep the character to the clips carrying these tags, e.g. \"style=elderly\" or "
                        "\"style=elderly & gait=walk\" (docs/styles.md; 'mmrl db info' lists the tags)")
    p.add_argument("--compressed", default=None, metavar="FILE",
                   help="play a compressed controller (mmrl compress) instead of the database: the same policy, "
                        "its projector for the search and its stepper for playback (docs/compressed.md)")
    add_deploy_set(p)


def register_cli(sub) -> None:
    e = sub.add_parser("eval", help="measure a policy on its task with the full character: success, time, foot "
                       "sliding, against the raw mocap and a joystick")
    add_shared_options(e, motion=False)
    e.add_argument("--json", action="store_true", help="print one JSON object")
    e.add_argument("--no-peer", action="store_true",
                   help="skip the joystick at the policy's own speed (by default it runs on the first "
                        f"{PEER_EPISODES} of the same episodes, for the verdict)")
    e.add_argument("--line", type=count, default=0, metavar="N",
                   help="also run N joysticks at speeds from the data's slowest walk to its fastest run on all the "
                   "same episodes, and report the policy's IK-off foot sliding against that line at its own time "
                   "to target (0: none)")
    e.add_argument("--standing", type=lambda t: nonnegative_float(t, 60), default=3.0, metavar="SECONDS",
                   help="tasks that end at rest (arrive): after each success play on this long at the same target "
                        f"and facing, on {STANDING_EPISODES} episodes (the same for the policy and its joystick), and "
                        "report the motion while standing "
                        "next to the raw mocap's idle frames (0: skip; default: 3)")
    e.add_argument("--per-request", nargs="?", const="", default=None, metavar="GROUPS",
                   help="evaluate once per value of these tag groups (comma-separated; default: the run's "
                        "request groups, else every group of the database) and print a table by request")
    e.set_defaults(func=cmd_eval)

    r = sub.add_parser("render", help="render a policy following a sequence of targets to MP4, GIF or a "
                       "standalone HTML page")
    add_shared_options(r, motion=True)
    r.add_argument("-o", "--output", help="output .mp4 or .gif")
    r.add_argument("--html", metavar="FILE", help="output a standalone .html page with a playback bar that opens "
                   "offline in any browser (needs mmrl[viewer]); with or instead of -o")
    r.add_argument("--size", default="640x360", help="video size WxH")
    r.add_argument("--still", metavar="PNG", help="also write the middle frame as a PNG")
    r.set_defaults(func=cmd_render)

    x = sub.add_parser("export-bvh", help="write generated motion as BVH on the input skeleton (+ .npz of positions)")
    add_shared_options(x, motion=True)
    x.add_argument("-o", "--output", required=True, help="output .bvh (the .npz is written beside it)")
    x.set_defaults(func=cmd_export)


# ---------------------------------------------------------------------- resolution
class Setup:
    """What a command runs: the task, its config and stage, the database and the policy."""

    def __init__(self, args: argparse.Namespace):
        from ..runs import RunDir

        run: Optional[RunDir] = RunDir(args.run, require_run=True) if args.run is not None else None
        if args.policy == "trained" and run is None:
            raise InputError("--policy trained: name the training run, e.g. mmrl eval runs/plane-seed0")
        if args.policy == "trained":
            args.policy = None
        saved = run.task if run is not None else None
        self.task = get_task(args.task) if args.task else (saved or get_task("plane"))
        if saved is not None and args.policy is None and self.task is not saved:
            raise InputError(f"{args.run} is a '{saved.name}' run; its policy cannot run --task {self.task.name} "
                             f"(pass --task {saved.name}, or --policy joystick)")
        self.stage = _check_stage(self.task, args.stage)
        self.config = run.task_config(self.task) if saved is not None else self.task.default_config()
        if args.db or args.data or run is None:
            self.db = database_from_args(args)
            if run is not None and args.policy is None:  # the run's policy on other data
                run.check_database(self.db, "--db" if args.db else "--data")
        else:
            self.db = run.database()
        self.config = deploy_config(self.task, self.config, args.set, self.db,
                                    trained=run is not None and args.policy is None)
        self.policy, self.policy_name = self._policy(args, run)
        self.options = dict(ik=not args.no_ik, foot_locking=not args.no_ik,
                            inertialization_halflife=0.0 if args.no_inertialization else 0.1)
        self.request = check_request(self.db, getattr(args, "request", "") or "")
        self.compressed = compressed_model(args, self.db, self.request)

    def _policy(self, args, run):
        from ..rl.policies import JoystickPolicy

        if args.policy is not None:
            return JoystickPolicy.preset(self.db, args.policy), args.policy
        if run is not None:
            return run.policy(), str(run.checkpoint)
        return JoystickPolicy.preset(self.db, "joystick"), "joystick"


def check_request(db, request: str) -> str:
    """``request`` in canonical form, or InputError naming what is wrong and the tags available."""
    from .. import _core

    if not request.strip():
        return ""
    try:
        return _core.select_request(db._db, request)[0]
    except ValueError as e:
        raise InputError(f"--request: {e}") from None


def compressed_model(args, db, request: str):
    """The compressed controller ``--compressed FILE`` names, for ``db`` (None without the flag);
    InputError with a ``request``: a compressed controller keeps to no tags."""
    if not getattr(args, "compressed", None):
        return None
    from ..compress.model import CompressedModel

    if request:
        raise InputError("--compressed: a compressed controller keeps to no tags; drop --request")
    return CompressedModel(args.compressed, db)


def _check_stage(task, stage: Optional[int]) -> Optional[int]:
    if stage is None:
        return None
    if not task.stages:
        staged = " or ".join(f"--task {n}" for n in task_names() if get_task(n).stages)
        raise InputError(f"--stage applies to {staged} only")
    if not 1 <= stage <= task.stages:
        raise InputError(f"--stage must be in 1..{task.stages}, got {stage}")
    return stage


def _follow(args):
    from ..rollout import follow

    s = Setup(args)
    return s, follow(s.task, s.db, s.policy, seconds=args.length, seed=args.seed, config=s.config, stage=s.stage,
                     request=s.request, compressed=s.compressed, **s.options)


# ---------------------------------------------------------------------- commands
def cmd_eval(args: argparse.Namespace) -> int:
    from ..rollout import evaluate_full_path

    s = Setup(args)
    if args.per_request is not None:
        return _eval_per_request(args, s)
    t0 = time.perf_counter()
    episodes = dict(seed=args.seed, config=s.config, stage=s.stage, request=s.request, **s.options)
    res = evaluate_full_path(s.task, s.db, s.policy, episodes=args.episodes, compressed=s.compressed, **episodes)
    if s.compressed is not None:
        res["compressed"] = str(s.compressed.path)
    from ..rl.policies import JoystickPolicy

    if not args.no_peer and not isinstance(s.policy, JoystickPolicy) and res.get("mean_speed_m_per_s"):
        speed = float(res["mean_speed_m_per_s"])
        peer = evaluate_full_path(s.task, s.db, JoystickPolicy(s.db, speed, arrive=True),
                                  episodes=min(args.episodes, PEER_EPISODES), **episodes)
        peer.pop("episode_results", None)
        res["joystick_at_speed"] = {"speed_m_per_s": speed, "episodes": min(args.episodes, PEER_EPISODES), **peer}
    if s.task.rests and args.standing > 0:
        _standing(res, s, args)
    if args.line:
        from ..eval.reference import against_line, joystick_line, joystick_speeds

        try:
            speeds = joystick_speeds(s.db, args.line, request=s.request)
        except ValueError as e:
            raise InputError(f"--line {args.line}: {e}") from None
        res.update(against_line(res, joystick_line(s.task, s.db, speeds=speeds, episodes=args.episodes, **episodes)))
    res.update({"policy": s.policy_name, "env": s.task.name, "seed": args.seed, "ik": not args.no_ik,
                "inertialization": not args.no_inertialization, "wall_time_s": time.perf_counter() - t0})
    res["verdict"] = verdict(res, args.run)
    res["episode_results"] = res.pop("episode_results")  # keep the per-episode list last
    if args.json:
        print(json.dumps(res))
        return 0
    print_evaluation(res, s, args.episodes)
    return 0


def _standing(res, s: "Setup", args) -> None:
    """The standing report (mmrl.eval.standing) of the policy and of its peer, on the same episodes."""
    from ..eval.standing import evaluate_standing

    options = dict(episodes=min(args.episodes, STANDING_EPISODES), seconds=args.standing, seed=args.seed,
                   config=s.config, request=s.request, **s.options)
    res["standing"] = evaluate_standing(s.task, s.db, s.policy, compressed=s.compressed, **options)
    if "joystick_at_speed" in res:
        from ..rl.policies import JoystickPolicy

        peer = JoystickPolicy(s.db, res["joystick_at_speed"]["speed_m_per_s"], arrive=True)
        res["joystick_at_speed"]["standing"] = evaluate_standing(s.task, s.db, peer, **options)
        res["joystick_at_speed"]["standing"].pop("episode_results")


def _f(v, digits: int = 2) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def print_evaluation(res, s: "Setup", episodes: int) -> None:
    """``mmrl eval``'s text: what ran, the numbers a person reads, the peers and a verdict."""
    where = f" (stage {res['stage']})" if "stage" in res else ""
    print(f"{s.policy_name} on the {s.task.name} task{where}: {episodes} episodes, seed {res['seed']}"
          + (f", request {s.request!r}" if s.request else "")
          + (f", compressed controller {s.compressed.path}" if s.compressed is not None else ""))
    print(f"  success             {100 * res['success_rate']:.1f}%")
    for k in (k for k in res if k.endswith("_rate") and k != "success_rate"):
        print(f"  {k.replace('_rate', ''):<19} {100 * res[k]:.1f}%")
    for k in (k for k in res if k.startswith("final_") and k.endswith("_median")):
        name, unit = k[len("final_"):-len("_median")].rsplit("_", 1)
        print(f"  {name.replace('_', ' '):<19} median {_f(res[k])} {unit}, p95 {_f(res[k[:-6] + 'p95'])} "
              f"(over successes)")
    t = res.get("mean_time_to_target_s")
    print("  time to target      " + ("n/a (no episode succeeded)" if t is None else f"{t:.2f} s (mean over successes)"))
    print(f"  mean speed          {_f(res.get('mean_speed_m_per_s'))} m/s")
    print(f"  foot sliding        {_f(res.get('foot_sliding_cm_per_s'), 1)} cm/s with IK, "
          f"{_f(res.get('foot_sliding_ik_off_cm_per_s'), 1)} without")
    print(f"  transitions         {_f(res.get('transitions_per_s'))} per s; pose jump p99 "
          f"{_f(res.get('pose_jump_p99_cm'), 1)} cm")
    if res.get("request_fidelity") is not None:
        print(f"  frames in request   {100 * res['request_fidelity']:.1f}%")
    floor = res.get("raw_mocap") or {}
    if floor:
        print(f"  raw mocap (the clips played straight, no IK): foot sliding {_f(floor.get('foot_sliding_cm_per_s'), 1)}"
              f" cm/s")
    peer = res.get("joystick_at_speed")
    if peer:
        print(f"  joystick at the same speed ({peer['speed_m_per_s']:.2f} m/s), first {peer['episodes']} of the same "
              f"episodes: success {100 * peer['success_rate']:.0f}%, time {_f(peer.get('mean_time_to_target_s'))} s, "
              f"sliding {_f(peer.get('foot_sliding_cm_per_s'), 1)} / {_f(peer.get('foot_sliding_ik_off_cm_per_s'), 1)}"
              f" cm/s (IK on / off)")
    for who, r in (("policy", res.get("standing")), ("joystick", (peer or {}).get("standing"))):
        if r is not None:
            from ..eval.standing import standing_line

            print(f"  standing, {who + ':':<9} {standing_line(r) or 'no episode succeeded'}")
    if res.get("joystick_line"):
        print("  joysticks on the same episodes (the equal-speed line):")
        print(f"    {'speed m/s':>9} {'success':>8} {'time s':>7} {'sliding IK off':>15} {'transitions/s':>14}")
        for r in res["joystick_line"]:
            print(f"    {r['speed_m_per_s']:>9.2f} {_f(r['success_rate'], 3):>8} {_f(r['mean_time_to_target_s']):>7} "
                  f"{_f(r['foot_sliding_ik_off_cm_per_s'], 1):>15} {_f(r['transitions_per_s']):>14}")
        ref, ratio = res["joystick_line_sliding_ik_off_cm_per_s"], res["sliding_ik_off_vs_joystick_line"]
        if ref is not None:
            print(f"  against the line at its time to target: {_f(res.get('foot_sliding_ik_off_cm_per_s'), 1)} vs "
                  f"{_f(ref, 1)} cm/s ({ratio:.2f}x)")
    print(f"verdict: {res['verdict']}")
    print(f"(took {res['wall_time_s']:.1f} s; --json prints every number)")


def verdict(res, run: Optional[str] = None) -> str:
    """One plain sentence on an evaluation: how often it succeeds, and how its feet compare
    with the joystick at its own speed (IK off: what the data and the matching give) and with
    the raw mocap."""
    rate = res["success_rate"]
    if rate >= 0.95:
        out = f"reliable: it succeeds in {100 * rate:.0f}% of episodes"
    elif rate >= 0.8:
        out = f"mostly works: it succeeds in {100 * rate:.0f}% of episodes"
    else:
        out = f"not reliable yet: it succeeds in only {100 * rate:.0f}% of episodes"
        if run:
            out += f" (train longer: mmrl train --resume {run} --seconds S)"
    ours = res.get("foot_sliding_ik_off_cm_per_s")
    peer = (res.get("joystick_at_speed") or {}).get("foot_sliding_ik_off_cm_per_s")
    floor = (res.get("raw_mocap") or {}).get("foot_sliding_cm_per_s")
    if ours is not None and peer:
        r = ours / peer
        how = ("are as steady as" if r <= 1.2 else "slide somewhat more than" if r <= 2 else
               "slide much more than")
        out += f"; its feet {how} the joystick's at the same speed ({r:.2f}x its sliding without IK"
        out += f", {ours / floor:.1f}x the raw mocap's)" if floor else ")"
    return out + "."


def _eval_per_request(args: argparse.Namespace, s: "Setup") -> int:
    """``mmrl eval --per-request``: one evaluation per tag value of the groups, on the same seed."""
    from .. import _core
    from ..motion.tags import request_group_list
    from ..rollout import evaluate_full_path

    groups = request_group_list(args.per_request) or request_group_list(getattr(s.config, "request_groups", ""))
    if not groups:
        groups = sorted({t.partition("=")[0] for t in s.db.tag_names})
    if not groups:
        raise InputError(f"--per-request: {_core.tags_available(s.db._db)}")
    base = s.request
    requests = []
    for g in groups:
        values = [t for t in s.db.tag_names if t.partition("=")[0] == g]
        if not values:
            raise InputError(f"--per-request: no tag group {g!r}; {_core.tags_available(s.db._db)}")
        for t in values:
            requests.append(f"{base} & {t}" if base else t)
    rows = []
    for req in requests:
        try:
            canon = _core.select_request(s.db._db, req)[0]
        except ValueError as e:  # e.g. a combination with the base request that selects nothing
            rows.append({"request": req, "error": str(e)})
            continue
        res = evaluate_full_path(s.task, s.db, s.policy, episodes=args.episodes, seed=args.seed, config=s.config,
                                 stage=s.stage, request=canon, **s.options)
        res.pop("episode_results", None)
        rows.append(res)
    if args.json:
        print(json.dumps({"policy": s.policy_name, "env": s.task.name, "seed": args.seed, "per_request": rows}))
        return 0
    print(f"{s.policy_name} on {s.task.name}: {args.episodes} episodes per request")
    print("| request | success | time to target (s) | mean speed (m/s) | sliding IK off | sliding IK on | "
          "transitions/s | pose jump p99 (cm) | frames inside |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        if "error" in r:
            print(f"| {r['request']} | {r['error']} |")
            continue
        print(f"| {r['request']} | {100 * r['success_rate']:.0f}% | {_f(r['mean_time_to_target_s'])} | "
              f"{_f(r.get('mean_speed_m_per_s'))} | {_f(r.get('foot_sliding_ik_off_cm_per_s'), 1)} | "
              f"{_f(r.get('foot_sliding_cm_per_s'), 1)} | {_f(r.get('transitions_per_s'))} | "
              f"{_f(r.get('pose_jump_p99_cm'), 1)} | {_f(100 * r['request_fidelity'], 1) + '%' if r.get('request_fidelity') is not None else 'n/a'} |")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    if args.output is None and args.html is None:
        raise InputError("mmrl render needs -o OUT.mp4|.gif, --html OUT.html, or both")
    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise InputError(f"--size expects WxH, got {args.size!r}") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise InputError(f"--size {args.size}: width and height must be 16-8192 pixels")
    if args.html is not None:
        output_path(args.html, "--html", (".html", ".htm"))
    if args.still is not None:
        output_path(args.still, "--still", (".png",))
    if args.output is None:
        return _render_html(args, *_follow(args))
    out = output_path(args.output, "-o", (".mp4", ".gif"))
    from ..viz.render import render_video

    s, rec = _follow(args)
    t0 = time.perf_counter()
    n = render_video(out, rec, s.db, width=w, height=h, still=args.still,
                     success_radius=float(getattr(s.config, "success_radius", 0.5)))
    dt = time.perf_counter() - t0
    print(f"wrote {out}: {n} frames ({n / s.db.fps:.1f} s) rendered in {dt:.2f} s ({n / dt:.0f} frames/s)")
    names = {0: "still going when the video ends", 1: "success", 2: "/".join(o for o in s.task.outcomes if o != "truncated") or "ended",
             3: "safety cap"}
    where = f"stage {int(rec['stage'])}, " if s.stage is not None or s.task.stages else ""
    print(f"{where}episodes: " + ", ".join(names.get(int(o), "?") for o in rec["outcomes"]))
    if args.still:
        print(f"wrote {args.still}")
    if args.html is not None:
        _render_html(args, s, rec)
    return 0


def _render_html(args: argparse.Namespace, s: "Setup", rec) -> int:
    from ..errors import require_extra

    require_extra("viser", "viewer", "mmrl render --html")
    from ..viewer.clips import recording_playback
    from ..viewer.export import write_html

    t0 = time.perf_counter()
    playback = recording_playback(Path(args.run or s.task.name).name, s.db, rec, s.task, s.config)
    size = write_html(args.html, playback)
    print(f"wrote {args.html}: {playback.num_frames} frames ({playback.num_frames / s.db.fps:.1f} s), "
          f"{size / 1e6:.1f} MB, in {time.perf_counter() - t0:.1f} s (opens offline from file://)")
    return 0


#: Recording keys written to the export's .npz besides the pose (plus the task's per-frame
#: keys, ``frame_keys``: targets and the scene's, such as obstacle corners).
EXPORT_KEYS = ("roots", "frames", "contacts", "episode", "outcomes")


def _check_positions_file(npz: Path) -> None:
    """export-bvh writes joint positions beside the BVH; it replaces an earlier export's file but
    never another file of that name (a database, say)."""
    if npz.exists():
        try:
            with np.load(npz, allow_pickle=False) as z:
                ours = {"positions", "joint_names", "parents"} <= set(z.files) and "format" not in z.files
        except Exception:
            ours = False
        if not ours:
            raise InputError(f"-o: {npz} exists and is not an earlier export-bvh output (export-bvh writes the joint "
                             f"positions there); choose another -o")


def cmd_export(args: argparse.Namespace) -> int:
    from .. import _core
    from ..io import atomic_write_bytes, atomic_write_npz

    out = output_path(args.output, "-o", (".bvh",))
    _check_positions_file(out.with_suffix(".npz"))
    s, rec = _follow(args)
    db = s.db
    motion = _core.motion_from_pose(db._db, np.ascontiguousarray(rec["local_translations"], np.float32),
                                    np.ascontiguousarray(rec["local_rotations"], np.float32), out.name)
    atomic_write_bytes(out, motion.to_bvh().encode())
    npz = out.with_suffix(".npz")
    atomic_write_npz(npz, positions=rec["positions"].astype(np.float32),
                     joint_names=np.array(db.joint_names, np.str_), parents=np.array(db.parents, np.int32),
                     fps=np.float32(db.fps), **{k: rec[k] for k in EXPORT_KEYS + tuple(rec["frame_keys"])})
    print(f"wrote {out} ({motion.num_frames} frames at {fps_text(db.fps)} fps) and {npz} (global joint positions, "
          f"meters)")
    return 0
