"""The SB3 hyperparameters a recipe sets: their types and ranges."""

from __future__ import annotations

import math
from typing import Any

from zodrive.errors import ZodriveError


POSITIVE_INTS = ("batch_size", "buffer_size", "gradient_steps", "target_update_interval", "n_steps", "n_epochs",
                 "policy_delay")
NON_NEGATIVE_INTS = ("learning_starts",)
UNIT = ("gamma", "tau", "exploration_fraction", "exploration_initial_eps", "exploration_final_eps", "gae_lambda")
MAX_BUFFER = 10_000_000
"""The largest replay buffer (SB3 allocates it whole at the start: 10^10 rows asked for 931 GiB)."""


def validate_hyperparameters(params: dict[str, Any], context: str) -> None:
    """Types and ranges of the SB3 hyperparameters a recipe sets (`--set hyperparameters.K=V`)."""
    for key, value in params.items():
        where = f"{context}: hyperparameters.{key}"
        if key in POSITIVE_INTS + NON_NEGATIVE_INTS:
            least = 0 if key in NON_NEGATIVE_INTS else 1
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ZodriveError(f"{where} must be an integer >= {least}, not {value!r}")
            if key == "buffer_size" and value > MAX_BUFFER:
                raise ZodriveError(f"{where} must be at most {MAX_BUFFER:,} (SB3 allocates the whole buffer at "
                                   f"once), not {value:,}")
        elif key in UNIT or key == "learning_rate":
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ZodriveError(f"{where} must be a number, not {value!r}")
            if key == "learning_rate" and value <= 0:
                raise ZodriveError(f"{where} must be > 0, not {value!r}")
            if key in UNIT and not 0 <= value <= 1:
                raise ZodriveError(f"{where} must be in [0, 1], not {value!r}")
        elif key == "policy_kwargs":
            _check_net_arch(value.get("net_arch") if isinstance(value, dict) else None, where)
        elif key == "train_freq" and not (isinstance(value, int) and not isinstance(value, bool) and value >= 1
                                          or isinstance(value, list)):
            raise ZodriveError(f"{where} must be an integer >= 1 (or [N, step|episode]), not {value!r}")


def _check_net_arch(arch: Any, where: str) -> None:
    """`net_arch`: layer widths (positive integers), as a list or SB3's dict of lists (pi, vf, qf)."""
    if arch is None:
        return
    lists = list(arch.values()) if isinstance(arch, dict) else [arch]
    for widths in lists:
        if not isinstance(widths, list) or not all(isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= 65_536
                                                   for w in widths):
            raise ZodriveError(f"{where}: net_arch must list layer widths (integers from 1 to 65536), not {arch!r}")
