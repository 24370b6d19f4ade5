"""zoo/q_ensemble.py: an ensemble acts on its members' mean Q-value less `pessimism` standard
deviations, and recombining a committed ensemble's zip keeps its weights byte for byte."""

from __future__ import annotations

import sys
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import DQN

ROOT = Path(__file__).resolve().parents[1]
sys.path.append(str(ROOT / "zoo"))  # the zoo's scripts import each other as the zoo runs them
q_ensemble = pytest.importorskip("q_ensemble")

SPACE = gym.spaces.Box(-1.0, 1.0, (5, 7), np.float32)


@pytest.mark.parametrize("pessimism", [0.0, 0.5, 2.0])
def test_the_ensemble_acts_on_the_mean_less_k_standard_deviations(pessimism: float) -> None:
    torch.manual_seed(0)
    ensemble = q_ensemble.QEnsemble(SPACE, members=3, net_arch=(16,), actions=3, pessimism=pessimism)
    obs = torch.rand(4, 5, 7) * 2 - 1
    obs[..., 0] = 1.0  # every vehicle row present
    with torch.no_grad():
        q = torch.stack([member(obs) for member in ensemble.members])
        expected = q.mean(dim=0) - pessimism * q.std(dim=0, correction=0)
        assert torch.allclose(ensemble(obs), expected)
    assert pessimism == 0 or not torch.allclose(expected, q.mean(dim=0))  # the members disagree: K matters


def test_recombining_keeps_the_weights_and_changes_only_the_rule(tmp_path: Path) -> None:
    source = ROOT / "models" / "zoo" / "intersection-attention-ensemble" / "seed-0"
    out = q_ensemble.recombine(source, tmp_path / "mean", 0.0)
    with zipfile.ZipFile(out) as new, zipfile.ZipFile(source / "model.zip") as old:
        assert new.read("policy.pth") == old.read("policy.pth")
    assert DQN.load(out, device="cpu").policy.q_net.features_extractor.pessimism == 0.0
    assert DQN.load(source / "model.zip", device="cpu").policy.q_net.features_extractor.pessimism == 0.5
