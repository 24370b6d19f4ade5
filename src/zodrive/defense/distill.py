"""`robust-train --method distill`: adversarially robust distillation of a DQN driver.

Why: SA-DQN and Algorithm 2 continue TD learning, and under this reward TD learning drifts to
the always-SLOWER fixed point (a constant decision is the cheapest robust one; measured in
the README). Distillation keeps the driver's behaviour as the target instead: collect the
states the teacher visits, then train a student (initialized as the teacher) to take the
teacher's action at every state *and* everywhere in the eps-ball around it (Madry-style
adversarial training on the supervised loss, the inner max by `pgd_steps` signed-gradient
steps inside the threat model: box, frozen presence):

    loss = CE(student(x), a*) + kappa * max_{x' in B(x, eps)} CE(student(x'), a*),  a* = argmax teacher(x)

Cf. policy distillation (Rusu et al., ICLR 2016) and adversarial training (Madry et al., ICLR
2018). The student is written as an ordinary SB3 DQN zip (the teacher's zip with the Q-network
weights replaced), so every command reads it; its outputs are logits, not Q-values.

With `teacher` set to an observation-reading baseline (`baseline:rules`,
`baseline:robust-rules@EPS`), that driver drives and labels instead: a student of a better
driver than the source model, made robust the same way (the student keeps the source model's
network shape and zip).
"""

from __future__ import annotations

import copy
import io
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.nn import functional as F

from zodrive.compute import one_torch_thread
from zodrive.errors import ZodriveError


@one_torch_thread  # small MLPs: one thread is fastest, and the result does not depend on the load
def distill(model: str, preset: dict[str, Any], eps: float, steps: int, out: Path, *, seed: int = 1,
            kappa: float = 1.0, pgd_steps: int = 5, epochs: int = 20, force: bool = False,
            teacher: str | None = None) -> Path:
    """Collect `steps` teacher states (training seeds `seed`, `seed` + 1, ...), train the
    robust student (initialized as `model`; the teacher is `model` itself unless `teacher`
    names an observation-reading baseline), write `out/model.zip` and `out/train.json`;
    returns the zip's path."""
    from zodrive.agents.baselines import get_baseline, is_baseline
    from zodrive.agents.loading import load_network, model_file
    from zodrive.agents.policies import load_victim
    from zodrive.agents.victims import network_victim
    from zodrive.attacks.threat import ThreatModel, worst_in_ball
    from zodrive.envs import attack_context, make_env
    from zodrive.evaluation.rollout import clean_states
    from zodrive.runinfo import write_json, write_run_info

    if (out / "model.zip").exists() and not force:
        raise ZodriveError(f"{out} already holds a model; use --force to overwrite it")
    source = load_network(model, preset)
    if source.algo != "dqn":
        raise ZodriveError("--method distill is implemented for DQN models")
    if teacher is not None and not (is_baseline(teacher) and get_baseline(teacher).reads == "observation"):
        raise ZodriveError(f"--teacher must be an observation-reading baseline (baseline:rules, "
                           f"baseline:robust-rules@EPS), not {teacher!r}")
    guide = load_victim(teacher, preset) if teacher else network_victim(source.net, "discrete", source.obs_shape)
    start = time.perf_counter()
    torch.manual_seed(seed)
    env = make_env(preset)
    states = clean_states(env, guide, seed, steps)
    env.close()
    context = attack_context(preset)
    low, high = context["bounds"]
    mask = torch.as_tensor(ThreatModel(eps=eps, features=context["features"]).mask(states.shape[1:]))
    x_all = torch.as_tensor(states, dtype=torch.float32)
    y_all = torch.as_tensor(guide.query(states).argmax(axis=1), dtype=torch.long)
    student = copy.deepcopy(source.net).train()
    opt = torch.optim.Adam(student.parameters(), lr=3e-4)
    gen = torch.Generator().manual_seed(seed)
    history = []
    for epoch in range(epochs):
        order = torch.randperm(len(x_all), generator=gen)
        total = 0.0
        for batch in order.split(256):
            x, y = x_all[batch], y_all[batch]
            x_adv = worst_in_ball(lambda z: F.cross_entropy(student(z.reshape(len(z), -1)), y, reduction="none"),
                                  x, eps, pgd_steps, mask, low, high)
            loss = F.cross_entropy(student(x.reshape(len(x), -1)), y) \
                + kappa * F.cross_entropy(student(x_adv.reshape(len(x), -1)), y)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * len(batch)
        history.append(round(total / len(x_all), 4))
    student.eval()
    with torch.no_grad():
        agree = float((student(x_all.reshape(len(x_all), -1)).argmax(dim=1) == y_all).float().mean())
    method = {"name": "robust-distillation", "teacher": teacher or "the source model", "eps": eps, "kappa": kappa,
              "pgd_steps": pgd_steps, "epochs": epochs, "states": steps,
              "reference": "Rusu et al. 2016; Madry et al. 2018"}
    write_run_info(out, {"source_model": str(model_file(model)), "preset": preset, "method": method}, seed)
    _write_zip(model_file(model), student, out / "model.zip")
    wall = time.perf_counter() - start
    write_json(out / "train.json", {
        "algo": "dqn", "kind": "distill", "source_model": str(model_file(model)), "method": method,
        "total_timesteps": steps, "seed": seed, "loss_per_epoch": history, "clean_agreement": round(agree, 4),
        "wall_time_s": round(wall, 1), "steps_per_s": round(steps / wall, 1)})
    return out / "model.zip"


def _write_zip(source: Path, student: torch.nn.Sequential, target: Path) -> None:
    """The teacher's SB3 zip with its Q-network (and target network) weights replaced."""
    with zipfile.ZipFile(source) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    weights = torch.load(io.BytesIO(members["policy.pth"]), map_location="cpu", weights_only=True)
    layers = [m for m in student if isinstance(m, torch.nn.Linear)]
    for prefix in ("q_net.q_net", "q_net_target.q_net"):
        indices = sorted({int(k.split(".")[2]) for k in weights if k.startswith(prefix + ".")})
        if len(indices) != len(layers):
            raise ZodriveError(f"{source}: unexpected Q-network layout")
        for index, layer in zip(indices, layers):
            weights[f"{prefix}.{index}.weight"] = layer.weight.detach().clone()
            weights[f"{prefix}.{index}.bias"] = layer.bias.detach().clone()
    buf = io.BytesIO()
    torch.save(weights, buf)
    members["policy.pth"] = buf.getvalue()
    members.pop("policy.optimizer.pth", None)  # the teacher's optimizer state no longer fits
    tmp = target.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    tmp.replace(target)
