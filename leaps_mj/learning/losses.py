"""Returns and losses of the sub-policy trainer: n-step returns, A2C, behaviour cloning, auxiliary heads.

Pure functions of tensors (and the config's coefficients), kept apart from
the rollout loop so that any source of unrolls (the local vector env, remote
workers) feeds the same update.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from leaps_mj.learning import nets
from leaps_mj.learning.policy_config import TrainConfig


def n_step_returns(rewards: np.ndarray, discounts: np.ndarray, next_values: np.ndarray,
                   bootstrap: np.ndarray) -> np.ndarray:
    """n-step returns of an unroll, bootstrapped where the unroll or episode ends.

    ``R_t = r_t + d_t * (V(s_{t+1}) if bootstrap_t else R_{t+1})``.

    Args:
      rewards: (T, B) reward of the step from s_t.
      discounts: (T, B) γ times the environment's discount of that step
        (0 after a success, γ at a horizon truncation).
      next_values: (T, B) value estimates of s_{t+1}.
      bootstrap: (T, B) bool; True where R_{t+1} is not available: at the
        last step of the unroll and where s_{t+1} ends its episode.

    Returns:
      (T, B) returns.

    Raises:
      ValueError: if the shapes differ or the last step does not bootstrap.
    """
    shapes = {a.shape for a in (rewards, discounts, next_values, bootstrap)}
    if len(shapes) != 1 or rewards.ndim != 2:
        raise ValueError(f"rewards, discounts, next_values, bootstrap must share one (T, B) shape, got {shapes}")
    if not np.all(bootstrap[-1]):
        raise ValueError("bootstrap[-1] must be all True: the unroll's last step has no R_{t+1}")
    returns = np.zeros(rewards.shape, dtype=np.float64)
    following = next_values[-1]
    for t in reversed(range(rewards.shape[0])):
        following = np.where(bootstrap[t], next_values[t], following)
        returns[t] = rewards[t] + discounts[t] * following
        following = returns[t]
    return returns


def masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return (x * mask).sum() / mask.sum().clamp(min=1.0)


def a2c_loss(logits: torch.Tensor, values: torch.Tensor, actions: torch.Tensor, returns: torch.Tensor,
             valid: torch.Tensor, config: TrainConfig) -> tuple[torch.Tensor, dict[str, float]]:
    """The A2C loss of an unroll (all tensors (T, B, ...); ``valid`` masks steps).

    Returns:
      (loss, scalars for logging).
    """
    dist = torch.distributions.Categorical(logits=logits)
    advantages = returns - values.detach()
    if config.normalize_advantages:
        mean = masked_mean(advantages, valid)
        std = masked_mean((advantages - mean) ** 2, valid).sqrt()
        advantages = (advantages - mean) / (std + 1e-8)
    policy_loss = -masked_mean(dist.log_prob(actions) * advantages, valid)
    value_loss = 0.5 * masked_mean((returns - values) ** 2, valid)
    entropy = masked_mean(dist.entropy(), valid)
    logits_l2 = masked_mean((logits ** 2).mean(-1), valid)
    loss = policy_loss + config.value_coef * value_loss - config.entropy * entropy + config.logits_l2 * logits_l2
    return loss, {"policy_loss": policy_loss.item(), "value_loss": value_loss.item(),
                  "entropy": entropy.item(), "logits_l2": logits_l2.item()}


def bc_loss(logits: torch.Tensor, labels: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, float]:
    """Cross-entropy to the expert labels over valid steps, and the accuracy."""
    ce = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), labels.reshape(-1).clamp(min=0),
                         reduction="none").reshape(labels.shape)
    accuracy = masked_mean((logits.argmax(-1) == labels).float(), valid).item()
    return masked_mean(ce, valid), accuracy


def aux_loss(outputs: dict[str, torch.Tensor], labels: dict[str, torch.Tensor],
             valid: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """The auxiliary losses of an unroll, summed with equal weights (all tensors (T, B, ...)).

    Binary cross-entropy of the room-view strips and of the room-type bits,
    Huber loss of the geodesic distance in units of ``nets.AUX_DISTANCE_SCALE``
    metres, clipped at 2 units (beyond that the target is simply far).

    Args:
      outputs: :meth:`leaps_mj.learning.nets.ActorCritic.aux_outputs`.
      labels: ``room_view`` (T, B, K + 1, C), ``semantic`` (T, B, K) and
        ``target_distance`` (T, B), as the training environments give them.
      valid: (T, B) mask of the steps that count.

    Returns:
      (loss, scalars for logging: the loss, the room-view accuracy and the
      distance error in metres).
    """
    view = F.binary_cross_entropy_with_logits(outputs["view"], labels["room_view"].float(), reduction="none")
    here = F.binary_cross_entropy_with_logits(outputs["here"], labels["semantic"].float(), reduction="none")
    distance = (labels["target_distance"].float() / nets.AUX_DISTANCE_SCALE).clamp(max=2.0)
    huber = F.smooth_l1_loss(outputs["distance"], distance, reduction="none")
    loss = masked_mean(view.mean((-1, -2)) + here.mean(-1) + huber, valid)
    view_accuracy = masked_mean(((outputs["view"] > 0) == (labels["room_view"] > 0)).float().mean((-1, -2)), valid)
    error = masked_mean((outputs["distance"].clamp(max=2.0) - distance).abs(), valid) * nets.AUX_DISTANCE_SCALE
    return loss, {"aux_loss": loss.item(), "aux_view_accuracy": view_accuracy.item(),
                  "aux_distance_error": error.item()}
