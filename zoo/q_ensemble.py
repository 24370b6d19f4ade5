"""Build one SB3 DQN zip whose Q-values are the mean of zoo runs' last checkpoints.

A run's checkpoints after exploration ends are about equally good and make different mistakes;
averaging their Q-values uses all of them instead of betting on the one that looked best on a set
of tuning seeds. The zip is a plain SB3 DQN: its features extractor (`QEnsemble`, below) holds the
members, each a whole Q-network of the run's architecture with its own weights, and outputs their
mean Q-values; the Q-head after it is the identity. Nothing is trained and no seed is read.

`--pessimism K` makes it act on the mean less K times the members' standard deviation (a lower
confidence bound): where the members disagree, it prefers the action they agree is good. K = 0,
the default, writes the plain mean's weights (`policy.pth`), byte for byte. `--from ENSEMBLE` recombines the members
held in an ensemble's own zip (the run checkpoints are not in the repository).

Its zips load in zodrive with `zoo/` on PYTHONPATH and `--trust-model`, as the attention runs do.

Run: PYTHONPATH=zoo python zoo/q_ensemble.py RUN [RUN ...] OUT [--steps 42000 48000 54000 60000] [--pessimism 0]
     PYTHONPATH=zoo python zoo/q_ensemble.py --from ENSEMBLE OUT --pessimism K
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym
import highway_env  # noqa: F401  (registers the highway-env scenarios)
import torch
from ego_attention import EgoAttention  # zoo/ego_attention.py: the members' extractor
from stable_baselines3 import DQN
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, create_mlp
from torch import nn

from zodrive.runinfo import sha256

STEPS = (42_000, 48_000, 54_000, 60_000)  # the checkpoints after exploration ends (zoo/train.py: 70 % of 60,000)


class Member(nn.Module):
    """One Q-network, named as SB3's QNetwork names its parts, so a checkpoint's state dict loads as is."""

    def __init__(self, observation_space: gym.spaces.Box, net_arch: Sequence[int], actions: int) -> None:
        super().__init__()
        self.features_extractor = EgoAttention(observation_space)
        self.q_net = nn.Sequential(*create_mlp(self.features_extractor.features_dim, actions, list(net_arch)))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.q_net(self.features_extractor(obs))


class QEnsemble(BaseFeaturesExtractor):
    """(batch, vehicles, features) -> (batch, actions): the members' mean Q-values, less `pessimism`
    times their standard deviation (over members, population form)."""

    def __init__(self, observation_space: gym.spaces.Box, members: int = 4, net_arch: Sequence[int] = (64, 64),
                 actions: int = 3, pessimism: float = 0.0) -> None:
        super().__init__(observation_space, features_dim=actions)
        self.members = nn.ModuleList(Member(observation_space, net_arch, actions) for _ in range(members))
        self.pessimism = pessimism

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        q = torch.stack([member(obs) for member in self.members])
        if not self.pessimism:
            return q.mean(dim=0)
        return q.mean(dim=0) - self.pessimism * q.std(dim=0, correction=0)


def build(runs: Sequence[Path], out: Path, steps: Sequence[int] = STEPS, pessimism: float = 0.0) -> Path:
    """Write OUT/model.zip (the ensemble of each run's checkpoints at `steps`) and OUT/build.json."""
    paths = [run / "checkpoints" / f"step_{step}_steps.zip" for run in runs for step in steps]
    sources = [DQN.load(p, device="cpu") for p in paths]
    first = sources[0]
    env_ids = {json.loads((run / "train.json").read_text())["env_id"] for run in runs}
    if len(env_ids) != 1 or any(s.policy_kwargs != first.policy_kwargs or s.gamma != first.gamma for s in sources):
        raise SystemExit(f"{', '.join(map(str, runs))}: not one scenario, network and discount")
    actions = int(first.action_space.n)
    shape = {"members": len(paths), "net_arch": first.policy_kwargs["net_arch"], "actions": actions}
    model = _ensemble(env_ids.pop(), first.gamma, shape, pessimism)
    with torch.no_grad():
        for network in (model.policy.q_net, model.policy.q_net_target):
            for member, source in zip(network.features_extractor.members, sources, strict=True):
                member.load_state_dict(source.policy.q_net.state_dict())
            head = network.q_net[0]  # net_arch=[]: one Linear(actions, actions)
            head.weight.copy_(torch.eye(actions))
            head.bias.zero_()
    return _save(model, out, {"script": "zoo/q_ensemble.py", "runs": [str(run) for run in runs], "steps": list(steps),
                              "members": {str(p): sha256(p) for p in paths}}, pessimism)


def recombine(ensemble: Path, out: Path, pessimism: float) -> Path:
    """Write OUT/model.zip: the members of ENSEMBLE (a folder `build` wrote) under `pessimism`."""
    record = json.loads((ensemble / "build.json").read_text())
    source = DQN.load(ensemble / "model.zip", device="cpu")
    shape = {k: v for k, v in source.policy_kwargs["features_extractor_kwargs"].items() if k != "pessimism"}
    env_id = json.loads((Path(record["runs"][0]) / "train.json").read_text())["env_id"]
    model = _ensemble(env_id, source.gamma, shape, pessimism)
    model.policy.load_state_dict(source.policy.state_dict())
    record |= {"from": str(ensemble), "from_sha256": sha256(ensemble / "model.zip")}
    record.pop("pessimism", None)
    return _save(model, out, record, pessimism)


def _ensemble(env_id: str, gamma: float, shape: dict, pessimism: float) -> DQN:
    """An untrained DQN: a QEnsemble of `shape` (under `pessimism`) as its features extractor, then one
    Linear(actions, actions) as its head."""
    if pessimism:  # only then, so that K = 0 writes the plain mean's zip as before
        shape = shape | {"pessimism": pessimism}
    return DQN("MlpPolicy", gym.make(env_id), gamma=gamma, device="cpu", seed=0, policy_kwargs={
        "features_extractor_class": QEnsemble, "net_arch": [], "features_extractor_kwargs": shape})


def _save(model: DQN, out: Path, record: dict, pessimism: float) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / "model.zip")
    record |= {"pessimism": pessimism} if pessimism else {}
    (out / "build.json").write_text(json.dumps(record, indent=2) + "\n")
    return out / "model.zip"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="*", help="run folders written by zoo/train.py --net attention")
    parser.add_argument("out", type=Path)
    parser.add_argument("--steps", type=int, nargs="+", help=f"each run's checkpoints to combine (default: {STEPS})")
    parser.add_argument("--pessimism", type=float, default=0.0, metavar="K",
                        help="act on mean - K * std of the members' Q-values (default: %(default)s, the mean)")
    parser.add_argument("--from", dest="ensemble", type=Path, metavar="ENSEMBLE",
                        help="recombine the members of an ensemble folder this script wrote, instead of RUNs")
    args = parser.parse_args()
    if args.pessimism < 0:
        parser.error("--pessimism must be >= 0")
    if bool(args.runs) == bool(args.ensemble):
        parser.error("give RUN folders or --from ENSEMBLE, not both or neither")
    if args.ensemble and args.steps:
        parser.error("--steps picks run checkpoints; --from reads the members the ensemble already holds")
    if (args.out / "model.zip").exists():  # never overwritten; zoo/train_all.sh resumes through it
        print(f"{args.out / 'model.zip'} exists: skipped")
        return
    if args.ensemble:
        print(f"wrote {recombine(args.ensemble, args.out, args.pessimism)}")
    else:
        print(f"wrote {build(args.runs, args.out, args.steps or STEPS, args.pessimism)}")


if __name__ == "__main__":
    main()
