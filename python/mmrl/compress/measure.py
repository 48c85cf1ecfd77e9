"""What ``mmrl compress`` measures of its networks (docs/compressed.md): the decompressor's joint
error on held-back clips, the stepper's after a rollout, the projector's against the search."""
from __future__ import annotations

from typing import Dict, Optional

import numpy as np

from .networks import _positions, projector_queries


def stage_metrics(stage, nets, data, s_all, norms, matcher, device, n: int = 256,
                  seconds: float = 2.0) -> Dict[str, float]:
    """A stage's measure on the database (fixed draws, so the numbers compare across checkpoints):
    the decompressor's held-back joint error; the stepper's joint error after rolling out
    ``seconds`` from a true state; the projector's: how often its answer decodes to the pose of
    the search's own answer within 5 cm (mean joint error), and that mean error."""
    import torch

    if stage == "decompressor":
        held = holdout_error(nets["compressor"], nets["decompressor"], data, device)
        return {} if held is None else {"holdout_joint_error_cm": held}
    rng = np.random.default_rng(12345)
    was = {k: v.training for k, v in nets.items()}
    for v in nets.values():
        v.eval()
    try:
        with torch.no_grad():
            if stage == "stepper":
                W = int(round(seconds * 30))
                starts = data.windows(W + 1)
                if starts.size == 0:
                    return {}
                t = rng.choice(starts, n)
                cur = s_all[torch.as_tensor(t, device=device)]
                for _ in range(W):
                    cur = cur + nets["stepper"](cur)
                poses = decode_states(nets, data, cur, *norms, device)
                return {"stepper_joint_error_cm": float(joint_errors_cm(data, t + W, poses).mean())}
            q = projector_queries(data, rng, n, 0.5)
            nearest, _ = matcher.match(q, None, None)
            pred = nets["projector"](torch.as_tensor(q, device=device))
            err = joint_errors_cm(data, nearest, decode_states(nets, data, pred, *norms, device))
            return {"projector_joint_error_cm": float(err.mean()), "projector_match_rate": float((err < 5.0).mean())}
    finally:
        for k, v in nets.items():
            v.train(was[k])


def decode_states(nets, data, states, z_mean, z_std, device) -> np.ndarray:
    """Raw poses of torch states [X, Zn] through the decompressor (Zn de-normalized by the
    database's latent statistics z_mean, z_std)."""
    import torch

    nx = data.x.shape[1]
    z = states[:, nx:] * z_std + z_mean
    mean, std = torch.as_tensor(data.y_mean, device=device), torch.as_tensor(data.y_std, device=device)
    return (nets["decompressor"](torch.cat([states[:, :nx], z], 1)) * std + mean).cpu().numpy()


def reconstruct(comp, decomp, data, frames: np.ndarray, device=None) -> np.ndarray:
    """Raw poses (len(frames), 9J + 5) of ``frames`` through the compressor and decompressor."""
    import torch

    device = device or next(decomp.parameters()).device
    with torch.no_grad():
        y = torch.as_tensor(data.y[frames], device=device)
        mean, std = torch.as_tensor(data.y_mean, device=device), torch.as_tensor(data.y_std, device=device)
        z = comp((y - mean) / std)
        out = decomp(torch.cat([torch.as_tensor(data.x[frames], device=device), z], 1)) * std + mean
    return out.cpu().numpy()


def joint_errors_cm(data, frames: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Per frame, the mean over joints of |p - p_true| (cm), character frame."""
    import torch

    J = len(data.parents)
    with torch.no_grad():
        p = _positions(torch.as_tensor(poses), data.parents, J)
        q = _positions(torch.as_tensor(data.y[frames]), data.parents, J)
    return (100.0 * (p - q).norm(dim=-1).mean(-1)).numpy()


def holdout_error(comp, decomp, data, device) -> Optional[float]:
    """Mean joint position error (cm) over the held-back clips' frames (None without them)."""
    frames = data.holdout_frames
    if frames.size == 0:
        return None
    frames = frames[:: max(1, frames.size // 4096)]
    was = comp.training, decomp.training
    comp.eval(), decomp.eval()
    err = float(joint_errors_cm(data, frames, reconstruct(comp, decomp, data, frames, device)).mean())
    comp.train(was[0]), decomp.train(was[1])
    return err
