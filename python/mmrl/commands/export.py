"""``mmrl export RUN``: a trained run for an engine.

- ``-o controller.mmrl``: the controller file the C++ runtime (``mmrl_runtime``) loads: the
  database, the policy and the task's numbers in one versioned binary file (docs/runtime.md);
- ``--onnx policy.onnx``: the policy alone as ONNX (raw observation -> action), checked with
  onnxruntime against the torch policy on observations of the task's own episodes.

(``mmrl export-bvh`` writes generated motion as BVH; see ``mmrl.commands.run``.)
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from ..errors import InputError
from .common import add_data_options, add_deploy_set, deploy_config, output_path, positive_int, run_database


def register_cli(sub) -> None:
    x = sub.add_parser("export", help="export a trained run: a controller file for the C++ runtime and/or the "
                       "policy as ONNX")
    x.add_argument("run", metavar="RUN", help="a training run directory")
    add_data_options(x)
    x.add_argument("-o", "--output", metavar="FILE", help="write the controller file (.mmrl) for mmrl_runtime")
    x.add_argument("--onnx", metavar="FILE", help="write the policy as ONNX (needs mmrl[onnx])")
    x.add_argument("--compressed", metavar="FILE", help="with -o: a compressed controller file, the networks of "
                   "FILE (mmrl compress) in place of the database (docs/compressed.md)")
    x.add_argument("--starts", type=positive_int, default=None, metavar="K",
                   help="with --compressed: start frames kept for the characters (default: 8)")
    x.add_argument("--check-observations", type=positive_int, default=512, metavar="N",
                   help="observations the ONNX check compares on (default: 512)")
    add_deploy_set(x)
    x.set_defaults(func=cmd_export)


def sample_observations(task, db, config, policy, count: int, seed: int = 0) -> np.ndarray:
    """``count`` observations of ``task``'s fast path under ``policy`` (the first step of
    each episode and the ones after it), so a check sees what the policy sees."""
    from ..rollout import policy_actions

    envs = max(1, min(64, count))
    env = task.make_vector_env(envs, db=db, config=config, num_threads=1)
    obs, _ = env.reset(seed=seed)
    rows = [obs]
    while sum(len(r) for r in rows) < count:
        obs, *_ = env.step(policy_actions(policy, obs, layout=env.observation_layout))
        rows.append(obs)
    env.close()
    return np.concatenate(rows)[:count].astype(np.float32)


def cmd_export(args: argparse.Namespace) -> int:
    from ..runs import RunDir

    if args.output is None and args.onnx is None:
        raise InputError("export: nothing to write; pass -o FILE (controller) and/or --onnx FILE")
    if args.compressed and args.output is None:
        raise InputError("export: --compressed writes a controller file; pass -o FILE")
    if args.starts is not None and not args.compressed:
        raise InputError("--starts applies with --compressed only")
    args.starts = args.starts or 8
    for flag, path, wrong, right in (("-o", args.output, ".onnx", "--onnx"), ("--onnx", args.onnx, ".mmrl", "-o")):
        if path is not None and str(path).lower().endswith(wrong):
            raise InputError(f"{flag} {path}: {flag} writes {'a controller file' if flag == '-o' else 'ONNX'}; "
                             f"for a {wrong} file use {right}")
    for name in ("output", "onnx"):
        if getattr(args, name) is not None:
            output_path(getattr(args, name), "-o" if name == "output" else "--onnx")
    run = RunDir(args.run, require_run=True)
    task = run.task
    policy, db = run.policy(), run_database(run, args)
    config = deploy_config(task, run.task_config(task), args.set, db)
    if args.output is not None:
        from ..export.runtime_export import write_controller

        t0 = time.perf_counter()
        if args.compressed:
            from ..compress.model import CompressedModel
            from ..export.compressed_export import write_compressed_controller

            try:
                size = write_compressed_controller(args.output, db, policy, task, config,
                                                   CompressedModel(args.compressed, db), args.starts)
            except ValueError as e:
                raise InputError(f"export --compressed: {e}") from None
            print(f"wrote {args.output}: {size / 1e6:.2f} MB, the compressed networks of {args.compressed} and "
                  f"{args.starts} start windows, {db.num_joints} joints ({time.perf_counter() - t0:.1f} s)")
        else:
            size = write_controller(args.output, db, policy, task.name, config)
            print(f"wrote {args.output}: {size / 1e6:.1f} MB, {db.num_frames} frames, {db.num_joints} joints "
                  f"({time.perf_counter() - t0:.1f} s)")
    if args.onnx is not None:
        from ..export.onnx_export import check_onnx, export_onnx

        env = task.make_vector_env(1, db=db, config=config, num_threads=1)
        low, high = env.single_action_space.low, env.single_action_space.high
        request_tags = env.request_tags
        env.close()
        export_onnx(policy, args.onnx, low, high, request_tags)
        obs = sample_observations(task, db, config, policy, args.check_observations)
        error = check_onnx(args.onnx, policy, obs, low, high)
        if request_tags:
            print(f"{args.onnx}: inputs 'obs' and 'request' ({len(request_tags)} floats: {', '.join(request_tags)})")
        print(f"wrote {args.onnx}: onnxruntime vs torch over {len(obs)} observations: max |difference| "
              f"{error['clipped_action']:.1e} (the env's clipped action), {error['action']:.1e} (raw action; "
              f"{error['action_relative']:.1e} relative)")
    return 0
