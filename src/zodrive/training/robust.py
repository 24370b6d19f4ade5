"""`zodrive robust-train`: continue a trained agent with a robustness method.

- `at`: the paper's Algorithm 2 (adversarial training with ZO-SignSGD at `eps`), kept for
  comparison.
- `sa`: the state-adversarial regularizer on clean observations: SA-DQN
  (`agents.dqn_variants.SADQN`) or SA-DDPG (`agents.state_adversarial.SADDPG`).
- `distill`: adversarially robust distillation of the model's own decisions (or of a
  `--teacher` baseline's) on the states the teacher visits (`defense.distill`); `steps` is the
  number of states collected; with `dagger` (rounds), behaviour cloning with DAgger
  (`defense.distill.dagger_distill`), `steps` states per round: into a DQN's Q-network, or
  into a DDPG/TD3 actor from a `--teacher` that may read the simulator (`baseline:idm-mobil`).
`at` and `sa` continue from the model's weights with the same warm-buffer start as Algorithm 2;
`distill` starts its student from them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from zodrive.policies.loading import model_algo, model_file
from zodrive.attacks.spec import load_attack
from zodrive.training.adversarial import adversarial_train
from zodrive.envs import attack_context, observation_shape
from zodrive.errors import ZodriveError

METHODS = ("at", "sa", "distill")


def robust_train(model: str, preset: dict[str, Any], method: str, eps: float | None, steps: int, out: Path, *,
                 seed: int = 1, warmup: int = 1000, kappa: float = 0.5, pgd_steps: int = 5,
                 progress_bar: bool = True, trust: bool = False, force: bool = False,
                 teacher: str | None = None, epochs: int = 20, dagger: int | None = None) -> Path:
    if method not in METHODS:
        raise ZodriveError(f"unknown method {method!r} (known: {', '.join(METHODS)})")
    cloning = method == "distill" and kappa == 0  # no adversarial term: no radius to train against
    if eps is None and not cloning:
        raise ZodriveError(f"--method {method} needs --eps (the L-inf radius to train against)")
    if eps is not None and not eps > 0:
        raise ZodriveError(f"eps must be > 0, not {eps}")
    if method == "distill":  # supervised on the teacher's states: no SB3 training loop, nothing unpickled
        from zodrive.training.distill import distill

        return distill(model, preset, eps, steps, out, seed=seed, kappa=kappa, pgd_steps=pgd_steps, force=force,
                       teacher=teacher, epochs=epochs, dagger=dagger)
    if dagger is not None:
        raise ZodriveError("--dagger applies to --method distill")
    if teacher is not None:
        raise ZodriveError("--teacher applies to --method distill")
    assert eps is not None  # only distill clones without one (returned above)
    common: dict[str, Any] = {"seed": seed, "warmup": warmup, "progress_bar": progress_bar, "trust": trust,
                              "force": force}
    if method == "at":
        return adversarial_train(model, preset, load_attack("zo-signsgd").with_overrides(eps=eps), steps, out, **common)
    algo = model_algo(model_file(model))
    if algo not in ("dqn", "ddpg"):
        raise ZodriveError(f"--method sa is implemented for DQN (SA-DQN) and DDPG (SA-DDPG) models, not {algo}")
    from zodrive.training.dqn_variants import SADQN
    from zodrive.training.state_adversarial import SADDPG
    from zodrive.attacks.threat import ThreatModel

    context = attack_context(preset)
    low, high = context["bounds"]
    mask = ThreatModel(eps=eps, features=context["features"]).mask(observation_shape(preset))

    def configure(agent: SADQN | SADDPG) -> dict[str, Any]:
        agent.configure_robust(eps=eps, kappa=kappa, pgd_steps=pgd_steps, mask=mask, low=low, high=high,
                               total_steps=steps)
        return {"name": f"sa-{algo}", "eps": eps, "kappa": kappa, "pgd_steps": pgd_steps, "eps_ramp": 0.3,
                **({"hinge": 1.0} if algo == "dqn" else {}), "reference": "Zhang et al., NeurIPS 2020"}

    return adversarial_train(model, preset, None, steps, out, algo_class=SADQN if algo == "dqn" else SADDPG,
                             setup=configure, **common)
