"""Training the networks of learned motion matching (issue 27, docs/compressed.md): the
compressor and decompressor, then the stepper, then the projector.

The decompressor maps a frame's normalized matching features X (27) and a latent Z to its pose Y
(:mod:`mmrl.compress.pose`); the compressor finds Z from the pose, so that X and Z together
determine the frame. Trained together as an autoencoder whose bottleneck is Z, with the features
given. The losses follow the reference design (Holden et al. 2020, section 4.1): the pose itself
(normalized), joint positions by forward kinematics in the character frame, both as velocities
over consecutive frames too, and a small penalty on the latent and its change between frames.

    mmrl compress DB -o compressed.pt --seconds 600

shows progress, logs metrics.csv (and TensorBoard with mmrl[viz]) beside the output, saves a
checkpoint every ``checkpoint_every`` iterations (atomically), resumes with ``--resume``, and is
reproducible with a seed. It uses CUDA when present.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Dict, Optional, Sequence

import numpy as np

from .files import load_compressed, save_compressed, stage_of
from .measure import holdout_error, stage_metrics
from .networks import STAGES, CompressConfig, CompressData, _positions, build_networks, projector_queries


def _logger():
    """metrics.csv (appended on resume) and TensorBoard, with the compressor's columns."""
    from ..logs import MetricsLogger

    class CompressLogger(MetricsLogger):
        BASE_COLUMNS = ("step", "wall_s", "stage", "iteration", "learning_rate", "loss", "pose", "positions_m",
                        "velocity", "latent", "latent_velocity", "joint_error_cm", "holdout_joint_error_cm",
                        "features", "latent_error", "stepper_joint_error_cm", "projector_joint_error_cm",
                        "projector_match_rate")
        LOSS_KEYS = ("loss", "pose", "positions_m", "velocity", "latent", "latent_velocity", "features",
                     "latent_error")

    return CompressLogger


def losses(comp, decomp, data_t, idx, cfg: CompressConfig) -> Dict[str, Any]:
    """The decompressor's losses of one batch of (t, t + 1) pairs (``idx``: the t's)."""
    import torch

    x, y, mean, std, parents, J = data_t
    both = torch.cat([idx, idx + 1])
    yn = (y[both] - mean) / std
    z = comp(yn)
    out_n = decomp(torch.cat([x[both], z], 1))
    out = out_n * std + mean
    true_pos = _positions(y[both], parents, J)
    pos = _positions(out, parents, J)
    n = idx.shape[0]
    l_pose = (out_n - yn).abs().mean()
    l_pos = (pos - true_pos).abs().mean()
    l_vel = ((out_n[n:] - out_n[:n]) - (yn[n:] - yn[:n])).abs().mean() + \
        ((pos[n:] - pos[:n]) - (true_pos[n:] - true_pos[:n])).abs().mean()
    l_z = (z ** 2).mean()
    l_zv = (z[n:] - z[:n]).abs().mean()
    total = cfg.w_pose * l_pose + cfg.w_positions * l_pos + cfg.w_velocity * l_vel + cfg.w_latent * l_z + \
        cfg.w_latent_velocity * l_zv
    return {"loss": total, "pose": l_pose, "positions_m": l_pos, "velocity": l_vel, "latent": l_z,
            "latent_velocity": l_zv, "joint_error_cm": 100.0 * (pos - true_pos).norm(dim=-1).mean()}


def stepper_losses(stepper, s_all, idx, cfg: CompressConfig) -> Dict[str, Any]:
    """The stepper's losses over windows starting at ``idx``: rolled out from the true state
    [X, Zn] of the first frame, L1 on the states and on their changes per frame."""
    import torch

    W = cfg.stepper_window
    steps = torch.arange(W, device=idx.device)
    true = s_all[idx[:, None] + steps[None]]  # (B, W, D)
    cur, pred = true[:, 0], [true[:, 0]]
    for _ in range(W - 1):
        cur = cur + stepper(cur)
        pred.append(cur)
    pred = torch.stack(pred, 1)
    l_state = (pred - true).abs().mean()
    l_vel = ((pred[:, 1:] - pred[:, :-1]) - (true[:, 1:] - true[:, :-1])).abs().mean()
    nx = s_all.shape[1] - cfg.latent
    return {"loss": l_state + l_vel, "features": (pred[..., :nx] - true[..., :nx]).abs().mean(),
            "latent_error": (pred[..., nx:] - true[..., nx:]).abs().mean(), "velocity": l_vel}


def projector_losses(projector, s_all, q, nearest, nx: int) -> Dict[str, Any]:
    """The projector's losses: L1 to the state [X, Zn] of each query's nearest valid frame."""
    pred, true = projector(q), s_all[nearest]
    l_x = (pred[:, :nx] - true[:, :nx]).abs().mean()
    l_z = (pred[:, nx:] - true[:, nx:]).abs().mean()
    return {"loss": l_x + l_z, "features": l_x, "latent_error": l_z}


def _device(name: str):
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def _tensors(data: CompressData, device):
    import torch

    return (torch.as_tensor(data.x, device=device), torch.as_tensor(data.y, device=device),
            torch.as_tensor(data.y_mean, device=device), torch.as_tensor(data.y_std, device=device),
            list(data.parents), len(data.parents))


def latent_states(nets: Dict[str, Any], data: CompressData, device, chunk: int = 8192):
    """(every frame's state [X, Zn] (N, 27 + L) as a torch tensor on device, z_mean, z_std):
    the compressor's latents of the database, normalized."""
    import torch

    comp = nets["compressor"]
    mean, std = torch.as_tensor(data.y_mean, device=device), torch.as_tensor(data.y_std, device=device)
    was = comp.training
    comp.eval()
    zs = []
    with torch.no_grad():
        for a in range(0, data.y.shape[0], chunk):
            zs.append(comp((torch.as_tensor(data.y[a:a + chunk], device=device) - mean) / std))
    comp.train(was)
    z = torch.cat(zs)
    z_mean, z_std = z.mean(0), z.std(0).clamp_min(1e-3)
    return torch.cat([torch.as_tensor(data.x, device=device), (z - z_mean) / z_std], 1), z_mean, z_std


def train_compressed(db, out, cfg: Optional[CompressConfig] = None, *, seconds: Optional[float] = None,
                     resume: bool = False, progress: bool = True, log_dir=None,
                     stages: Optional[Sequence[str]] = None) -> Dict[str, Any]:
    """Train (or resume) the networks of ``db``'s compressed controller into ``out``, stage by
    stage (:data:`STAGES`); returns the last metrics (the held-back clips' joint error included).

    ``stages``: train these stages of the finished file ``out`` again, from fresh networks, with
    the whole budget (the others are kept); retraining the decompressor retrains every stage,
    since the later ones learn its latents."""
    import torch

    cfg = cfg or CompressConfig()
    out = Path(out)
    device = _device(cfg.device)
    torch.manual_seed(cfg.seed)
    data = CompressData.from_database(db, cfg.holdout_every)
    if data.train_pairs.size == 0:
        raise ValueError("the database has no pair of consecutive frames to train on")
    if len(cfg.stage_time) != len(STAGES) or not all(t >= 0 for t in cfg.stage_time) or sum(cfg.stage_time) <= 0:
        raise ValueError(f"stage_time: expected {len(STAGES)} shares >= 0, got {cfg.stage_time}")
    nets = build_networks(data.y.shape[1], data.x.shape[1], cfg)
    for net in nets.values():
        net.to(device)
    stage, start, saved = STAGES[0], 0, None
    plan = list(STAGES)
    if stages is not None:
        plan = [s_ for s_ in STAGES if s_ in set(stages)]
        unknown = sorted(set(stages) - set(STAGES))
        if unknown or not plan:
            raise ValueError(f"stages: expected some of {', '.join(STAGES)}, got {', '.join(stages)}")
        if "decompressor" in plan and plan != list(STAGES):
            raise ValueError("stages: retraining the decompressor retrains the stepper and the projector too "
                             "(they learn its latents); list all three")
        if not out.exists() or stage_of(load_compressed(out, db)) != "done":
            raise ValueError(f"stages: {out} must be a finished compressed file")
    if (resume or stages is not None) and out.exists():
        saved = load_compressed(out, db)
        retrained = set(plan) if stages is not None else set()  # these start from fresh networks
        for name in nets:
            if name in saved and STAGES[_first_stage(name)] not in retrained:
                nets[name].load_state_dict(saved[name])
        stage, start = stage_of(saved), int(saved.get("iteration", 0))
        if stages is not None:
            stage, start = plan[0], 0
    log_path = Path(log_dir or out.parent) / f"{out.stem}-metrics"
    log_path.mkdir(parents=True, exist_ok=True)
    offset = {name: sum(_stage_iterations(cfg, s) for s in STAGES[:k]) for k, name in enumerate(STAGES)}
    step0 = (offset[stage] + start) if stage in offset else sum(_stage_iterations(cfg, s) for s in STAGES)
    logger = _logger()(log_path, step0 if resume else None, tensorboard=True)
    t0, last = time.perf_counter(), {}
    # What earlier stages measured and how long they trained, carried into every later save.
    extra: Dict[str, Any] = {k: v for k, v in (saved or {}).items()
                             if isinstance(v, (int, float)) and k.endswith(("_iterations", "_cm", "_rate"))}
    try:
        todo = [n for n in plan if stage != "done" and STAGES.index(n) >= STAGES.index(stage)]
        for k, name in enumerate(todo):
            budget = None
            if seconds is not None:
                left = seconds - (time.perf_counter() - t0)
                shares = [cfg.stage_time[STAGES.index(n)] for n in todo[k:]]
                budget = max(0.0, left * shares[0] / max(sum(shares), 1e-9))
            resumed = name == stage and stages is None
            last = _train_stage(name, nets, data, cfg, db, out, device, logger, offset[name],
                                start if resumed else 0, saved if resumed else None, budget, progress, extra,
                                todo[k + 1] if k + 1 < len(todo) else "done")
            saved = None
    finally:
        logger.close()
    if stage == "done" and saved is not None:
        last = {"iteration": int(saved.get("iteration", 0))}
    held = holdout_error(nets["compressor"], nets["decompressor"], data, device)
    if held is not None:
        last["holdout_joint_error_cm"] = held
    last["stage"] = "done"
    return last


def _stage_iterations(cfg: CompressConfig, stage: str) -> int:
    return {"decompressor": cfg.iterations, "stepper": cfg.stepper_iterations,
            "projector": cfg.projector_iterations}[stage]


def _train_stage(stage, nets, data, cfg, db, out, device, logger, step_offset, start, saved, budget, progress,
                 extra, next_stage) -> Dict[str, Any]:
    """One stage's loop (resumable at any checkpoint: networks, Adam and the sampler's RNG)."""
    import torch

    iterations = _stage_iterations(cfg, stage)
    trained = {"decompressor": ("compressor", "decompressor"), "stepper": ("stepper",),
               "projector": ("projector",)}[stage]
    params = [p for n in trained for p in nets[n].parameters()]
    opt = torch.optim.Adam(params, lr=cfg.learning_rate)
    rng = np.random.default_rng([cfg.seed, STAGES.index(stage)])
    if saved is not None and start > 0:
        opt.load_state_dict(saved["optimizer"])
        rng.bit_generator.state = saved["rng"]  # the batches a run without the stop would have drawn
    sched = torch.optim.lr_scheduler.StepLR(opt, 1000, gamma=cfg.lr_decay, last_epoch=start - 1 if start else -1)
    data_t = _tensors(data, device)
    s_all, norms, znorm = None, {}, None
    if stage != "decompressor":
        s_all, z_mean, z_std = latent_states(nets, data, device)
        norms, znorm = {"z_mean": z_mean.cpu(), "z_std": z_std.cpu()}, (z_mean, z_std)
    windows = data.windows(cfg.stepper_window) if stage == "stepper" else None
    if stage == "stepper" and windows.size == 0:
        raise ValueError(f"no clip has stepper_window={cfg.stepper_window} frames")
    matcher = db.matcher if stage == "projector" else None
    from tqdm import tqdm

    bar = tqdm(total=iterations, initial=start, unit="it", desc=stage, disable=not progress)
    t0, it, last = time.perf_counter(), start, {}

    def save(done: bool):
        k = STAGES.index(stage)
        if done:  # the next stage starts from scratch: no optimizer or sampler state to keep
            state = {"stage": next_stage, "iteration": 0}
        else:
            state = {"stage": stage, "iteration": it, "optimizer": opt.state_dict(), "rng": rng.bit_generator.state}
        state = {**extra, **metrics, **state, f"{stage}_iterations": it}
        keep = {n: v for n, v in nets.items() if _first_stage(n) <= k}
        save_compressed(out, keep, data, cfg, db, {**state, **norms})

    metrics: Dict[str, Any] = {}

    try:
        for n in trained:
            nets[n].train()
        while it < iterations and (budget is None or time.perf_counter() - t0 < budget):
            res = _batch_losses(stage, nets, data, data_t, cfg, rng, windows, s_all, matcher, device)
            opt.zero_grad()
            res["loss"].backward()
            opt.step()
            sched.step()
            it += 1
            bar.update(1)
            checkpoint = it % cfg.checkpoint_every == 0
            if checkpoint or it % 200 == 0 or it == iterations:
                last = {k: float(v.detach()) for k, v in res.items()}
                last.update(step=step_offset + it, wall_s=time.perf_counter() - t0, stage=STAGES.index(stage),
                            iteration=it, learning_rate=opt.param_groups[0]["lr"])
                if checkpoint:
                    last.update(stage_metrics(stage, nets, data, s_all, znorm, matcher, device))
                    save(False)
                logger.write(last)
    finally:
        bar.close()
        for n in trained:
            nets[n].eval()
    last.update(stage_metrics(stage, nets, data, s_all, znorm, matcher, device))
    metrics.update({k: v for k, v in last.items() if k.endswith(("_cm", "_match_rate"))})
    save(it >= iterations or budget is not None)
    extra.update(metrics)
    extra[f"{stage}_iterations"] = it
    last["iteration"] = it
    return last


def _batch_losses(stage, nets, data, data_t, cfg, rng, windows, s_all, matcher, device) -> Dict[str, Any]:
    """One batch of ``stage``, drawn from ``rng``, and its losses."""
    import torch

    if stage == "decompressor":
        idx = torch.as_tensor(rng.choice(data.train_pairs, cfg.batch), device=device)
        return losses(nets["compressor"], nets["decompressor"], data_t, idx, cfg)
    if stage == "stepper":
        idx = torch.as_tensor(rng.choice(windows, cfg.batch), device=device)
        return stepper_losses(nets["stepper"], s_all, idx, cfg)
    q = projector_queries(data, rng, cfg.batch, cfg.projector_noise)
    nearest, _ = matcher.match(q, None, None)
    return projector_losses(nets["projector"], s_all, torch.as_tensor(q, device=device),
                            torch.as_tensor(nearest, device=device), data.x.shape[1])


def _first_stage(name: str) -> int:
    """The index of the stage that trains network ``name``."""
    return {"compressor": 0, "decompressor": 0, "stepper": 1, "projector": 2}[name]

